"""Fixtures of the in-process app tests: a real viser server on a free port, stopped at the end of each test."""

import pytest

from rrbc_viz.serve import serve
from tests.paths import EXAMPLE_CSV


@pytest.fixture
def app():
    a = serve(port=0)
    try:
        yield a
    finally:
        a.stop()


@pytest.fixture
def measured():
    a = serve(EXAMPLE_CSV, port=0)
    try:
        yield a
    finally:
        a.stop()
