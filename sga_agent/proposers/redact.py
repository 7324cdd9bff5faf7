"""Keep API keys out of messages: anything a proposer logs or raises passes through here."""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Mapping

#: Environment variables whose names match hold secrets (OPENAI_API_KEY, HF_TOKEN, ...).
SECRET_NAME = re.compile(r"KEY|TOKEN|SECRET|PASSWORD|CREDENTIAL", re.IGNORECASE)
#: Shorter values ("1", "true") are settings, not secrets, and replacing them would garble text.
MIN_SECRET_LENGTH = 8
MASK = "***"
_URL_USERINFO = re.compile(r"(?<=://)[^/@\s]+@")


def redact(text: str, environ: Mapping[str, str] | None = None) -> str:
    """``text`` with secret environment values and URL credentials replaced by ``***``.

    Parameters
    ----------
    text : str
        Any message, e.g. an error from a provider that echoes the key it was sent.
    environ : mapping, optional
        The environment to take secret values from (default: ``os.environ``).
    """
    environ = os.environ if environ is None else environ
    secrets = {
        value
        for name, value in environ.items()
        if SECRET_NAME.search(name) and len(value) >= MIN_SECRET_LENGTH
    }
    for value in sorted(secrets, key=len, reverse=True):
        text = text.replace(value, MASK)
    return _URL_USERINFO.sub(MASK + "@", text)


class RedactingFilter(logging.Filter):
    """Masks secrets in every record of the logger it is attached to (e.g. litellm's, which at
    DEBUG level can log a provider's raw error, key included)."""

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg = redact(record.getMessage())
        record.args = None
        return True
