"""The second of four shares of test_random_rig_frames_autocollimator.py's 108 random autocollimator rigs."""

from every_kind import rendered_rig_tests

test_more_random_autocollimator_rigs_render_a_frame_of_every_kind, test_more_different_autocollimator_rigs = \
    rendered_rig_tests("autocollimator", draws=108, distinct=15, parts=4, part=1)
