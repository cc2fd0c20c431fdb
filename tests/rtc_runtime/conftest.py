from __future__ import annotations

import pytest

from .helpers import Journal


@pytest.fixture
def journal() -> Journal:
    return Journal()
