"""Test-wide settings: hypothesis runs derandomised (the same examples every run, no example database), so the
suite is deterministic like every other seeded test here. Set HYPOTHESIS_PROFILE=explore to search afresh."""

import os

from hypothesis import settings

settings.register_profile("deterministic", derandomize=True, database=None, deadline=None, print_blob=True)
settings.register_profile("explore", deadline=None, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))
