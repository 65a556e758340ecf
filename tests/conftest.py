"""Shared test fixtures."""

from pathlib import Path

import pytest

from helpers import shared_data_or_skip


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """`../shared/data` beside the repository; skips the test when it is absent."""
    return shared_data_or_skip()
