"""Suite-wide settings.

Hypothesis explores new random examples on developers' machines, but CI (``CI=true``) runs a derandomized profile:
the same examples on every run, so a red CI always means a reproducible failure, never a lucky draw.
"""

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
    settings.load_profile("ci")
