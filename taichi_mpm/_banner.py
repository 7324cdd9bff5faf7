"""Imported first by :mod:`taichi_mpm`: Taichi prints no banner on import.

``ENABLE_TAICHI_HEADER_PRINT=1`` in the environment brings the banner back.
"""

import os

os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "False")
