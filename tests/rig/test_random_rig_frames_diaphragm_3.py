"""The third of four shares of test_random_rig_frames_diaphragm.py's 108 random diaphragm rigs."""

from every_kind import rendered_rig_tests

test_a_third_share_of_random_diaphragm_rigs_renders, test_different_diaphragm_rigs_in_a_third_share = \
    rendered_rig_tests("diaphragm", draws=108, distinct=15, parts=4, part=2)
