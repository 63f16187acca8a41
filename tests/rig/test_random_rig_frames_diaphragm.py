"""100 random diaphragm rigs (tests/rig/random_rigs.py), each rendered once in every kind it makes: the sun
sensor (4 spp, centroid within 0.5 px of the truth), a chessboard through its camera, and the aiming camera's
pair (divergent beam): the concentricity offset within 0.5 px of a second method's (the blurred pencil minus
the light lost into the hole, integrated on the screen plane).
The two methods live in two files so that the parallel runner gives each its own worker."""

import pytest
from every_kind import render_every_kind
from hypothesis import given
from random_rigs import build, draw, rig_dicts

SEEN: set[str] = set()


@pytest.mark.slow
@draw(108)  # derandomized hypothesis repeats a few draws: 108 asked give 100 distinct rigs or more
@given(rig_dicts("diaphragm"))
def test_random_diaphragm_rig_renders_a_frame_of_every_kind(d):
    SEEN.add(repr(d))
    render_every_kind(build(d))


@pytest.mark.slow
def test_100_different_diaphragm_rigs_were_rendered():
    assert len(SEEN) >= 100
