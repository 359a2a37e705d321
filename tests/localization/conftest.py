"""Fixtures of the localization tests."""

from __future__ import annotations

import pytest
from localization_helpers import corridor_graph


@pytest.fixture()
def corridor():
    """See :func:`localization_helpers.corridor_graph`."""
    return corridor_graph()
