"""The trajectory a fit leaves for reports: a few frames of positions, compactly encoded.

Reports draw the best law's motion from this artifact, written by the trusted fit, instead of
simulating the law again (which would mean loading its code). Positions are quantized to 16
bits over their bounding box (0.1 mm for a 1 m scene) and sent as base64 text inside the
Evaluation's JSON; non-finite positions (an unstable law) survive as NaN.
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

#: Frames kept from a trajectory (the first and the last included).
FRAMES = 31
_LEVELS = 65534  # 65535 marks a non-finite coordinate
_MISSING = 65535


def encode_positions(positions: np.ndarray, frames: int = FRAMES) -> dict[str, Any]:
    """``frames`` evenly spaced steps of ``positions`` (steps + 1, N, 3) as JSON-ready data."""
    steps = np.unique(np.linspace(0, positions.shape[0] - 1, frames).round().astype(int))
    kept = np.asarray(positions[steps], dtype=np.float64)
    finite = np.isfinite(kept)
    low = float(kept[finite].min()) if finite.any() else 0.0
    high = float(kept[finite].max()) if finite.any() else 1.0
    scale = (high - low) / _LEVELS or 1.0
    levels = np.where(finite, np.rint((np.where(finite, kept, low) - low) / scale), _MISSING)
    return {
        "steps": steps.tolist(),
        "shape": list(kept.shape),
        "low": low,
        "scale": scale,
        "uint16": base64.b64encode(levels.astype("<u2").tobytes()).decode("ascii"),
    }


def decode_positions(artifact: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """The steps and positions (frames, N, 3) of an :func:`encode_positions` artifact."""
    raw = np.frombuffer(base64.b64decode(artifact["uint16"]), dtype="<u2")
    levels = raw.reshape(artifact["shape"]).astype(np.float64)
    positions = np.where(levels == _MISSING, np.nan, artifact["low"] + levels * artifact["scale"])
    return np.asarray(artifact["steps"], dtype=int), positions
