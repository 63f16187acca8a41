"""The second of four shares of test_random_rig_frames_diaphragm.py's 108 random diaphragm rigs."""

from every_kind import rendered_rig_tests

test_more_random_diaphragm_rigs_render_a_frame_of_every_kind, test_more_different_diaphragm_rigs = \
    rendered_rig_tests("diaphragm", draws=108, distinct=15, parts=4, part=1)
