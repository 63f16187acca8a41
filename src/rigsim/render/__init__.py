"""Everything that imports mitsuba/drjit lives in this package, and only here.

Importing ``rigsim.render`` (or :mod:`rigsim.render.backend`, :mod:`rigsim.render.frame`) does not import mitsuba. Modules that need it
(:mod:`rigsim.render.plugins`, :mod:`rigsim.render.cube_mirror.sun_sensor`) call
:func:`rigsim.render.backend.ensure_variant` before touching mitsuba, which picks a libLLVM that
passed a subprocess self-test.
"""

from rigsim.render.backend import choose_variant, doctor_report, ensure_variant

__all__ = ["choose_variant", "doctor_report", "ensure_variant"]
