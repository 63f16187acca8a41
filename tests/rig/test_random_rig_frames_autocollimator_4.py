"""The last of four shares of test_random_rig_frames_autocollimator.py's 108 random autocollimator rigs."""

from every_kind import rendered_rig_tests

test_the_last_quarter_of_random_autocollimator_rigs_renders, test_different_autocollimator_rigs_in_the_last_quarter = \
    rendered_rig_tests("autocollimator", draws=108, distinct=15, parts=4, part=3)
