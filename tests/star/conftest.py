import pytest

from rigsim.star.field import StarSky
from rigsim.star.schema import load_star_rig


@pytest.fixture(scope="session")
def rig():
    return load_star_rig()


@pytest.fixture(scope="session")
def sky(rig):
    return StarSky(rig)
