"""Shared fixtures: the real data sets (``shared/`` beside the repository) and the shipped maps."""
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``shared/data`` beside the clone (CI puts it there); fail loudly if it is missing."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"real data folder {SHARED_DATA} is missing: clone next to shared/")
    return SHARED_DATA


@pytest.fixture(scope="session")
def karhula():
    """The shipped Karhula (Kotka) road graph (real OpenStreetMap extract, ODbL)."""
    from selfnav.roads.graph import packaged_map, read_roads

    return read_roads(packaged_map("kotka_karhula"))


@pytest.fixture(scope="session")
def helsinki():
    """The shipped central Helsinki road graph (real OpenStreetMap extract, ODbL)."""
    from selfnav.roads.graph import packaged_map, read_roads

    return read_roads(packaged_map("helsinki_centre"))
