"""108 random autocollimator rigs (tests/rig/random_rigs.py; 104 different), each rendered once in every kind it
makes: the sun sensor (4 spp, centroid within 0.5 px of the truth), a chessboard through its camera, and the
autocollimator's frame (64 spp): its centroid near the exact one (tolerance in every_kind.py), unless the truth flags
a cut beam. The draws are spread over four files by a hash of the rig (every_kind.share; 33, 29, 20 and 26 draws):
the parallel runner gives each file to the next free worker, which keeps the two workers' loads even."""

from every_kind import rendered_rig_tests

test_random_autocollimator_rigs_render_a_frame_of_every_kind, test_different_autocollimator_rigs_were_rendered = \
    rendered_rig_tests("autocollimator", draws=108, distinct=15, parts=4, part=0)
