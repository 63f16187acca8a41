"""108 random diaphragm rigs (tests/rig/random_rigs.py; 104 different), each rendered once in every kind it
makes: the sun sensor (4 spp, centroid within 0.5 px of the truth), a chessboard through its camera, and the
aiming camera's pair (divergent beam): the concentricity offset within 0.5 px of the closed form's (the blurred
pencil minus the light lost into the hole: rigsim.optics.screen_return). The draws are spread over four files by a
hash of the rig (every_kind.share) so that the parallel runner keeps both workers busy to the end (a diaphragm rig
takes 5-20 s; with two files the last one ran alone for minutes)."""

from every_kind import rendered_rig_tests

test_random_diaphragm_rigs_render_a_frame_of_every_kind, test_different_diaphragm_rigs_were_rendered = \
    rendered_rig_tests("diaphragm", draws=108, distinct=15, parts=4, part=0)
