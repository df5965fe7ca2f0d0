"""Shared fixtures: the real data sets (``shared/`` beside the repository) and the shipped maps."""
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def pytest_configure(config):
    # with two workers (``-n 2``), tests are sent one at a time, so that the long ones, sent
    # first (below), are spread over both and the workers end together: sent in batches of
    # consecutive tests, CI's two runs idled one worker for 90-110 s at their ends
    if getattr(config.option, "maxschedchunk", "no xdist") is None:
        config.option.maxschedchunk = 1


def pytest_collection_modifyitems(config, items):
    """The tests marked ``long`` first, each group in its collection order."""
    items.sort(key=lambda item: item.get_closest_marker("long") is None)
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
