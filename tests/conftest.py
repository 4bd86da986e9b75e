"""Test configuration: under CI, property tests use a fixed example sequence (derandomized),
so a red run can be reproduced and a green one is not luck; locally they explore anew."""

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")
