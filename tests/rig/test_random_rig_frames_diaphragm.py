"""100 random diaphragm rigs (tests/rig/random_rigs.py), each rendered once in every kind it makes: the sun
sensor (4 spp, centroid within 0.5 px of the truth), a chessboard through its camera, and the aiming camera's
pair (divergent beam): the concentricity offset within 0.5 px of a second method's (the blurred pencil minus
the light lost into the hole, integrated on the screen plane)."""

from every_kind import rendered_rig_tests

test_random_diaphragm_rig_renders_a_frame_of_every_kind, test_100_different_diaphragm_rigs_were_rendered = \
    rendered_rig_tests("diaphragm")
