import pytest

from rigsim.truth.star import StarSky
from rigsim.rig.load import load_star_rig


@pytest.fixture(scope="session")
def rig():
    return load_star_rig()


@pytest.fixture(scope="session")
def sky(rig):
    return StarSky(rig)
