"""108 random autocollimator rigs (tests/rig/random_rigs.py; at least 100 different), each rendered once in every
kind it makes: the sun sensor (4 spp, centroid within 0.5 px of the truth), a chessboard through its camera, and the
autocollimator's frame (64 spp): its centroid near the exact one (tolerance in every_kind.py), unless the truth flags
a cut beam. This file renders the even-numbered draws, ..._2.py the odd ones: this method's renders take four times
the diaphragm's, and the parallel runner gives each file its own worker."""

from every_kind import rendered_rig_tests

test_random_autocollimator_rigs_render_a_frame_of_every_kind, test_50_different_autocollimator_rigs_were_rendered = \
    rendered_rig_tests("autocollimator", draws=108, distinct=50, parts=2, part=0)
