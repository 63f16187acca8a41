"""Every user-facing error and warning of rigsim, in one hierarchy.

``rigsim`` prints any :class:`RigsimError` as one line (``rigsim: error: ...``) and exits 2 (3 for a
:class:`PoorFitError`: data that do not fit the model, docs/fit-judgement.md). The
message names the file or option, the field, the value and the allowed range. Library callers
catch :class:`RigsimError` (or the specific class); the classes that describe bad input also
derive from ``ValueError`` so that generic ``except ValueError`` code keeps working.
"""

from __future__ import annotations

__all__ = ["RigsimError", "CliError", "RigError", "GeometryError", "SearchError", "DatasetError", "InputError", "ViewError",
           "ExportError", "ResourceError", "PoorFitError", "POOR_FIT_EXIT", "GeometryWarning", "SaturationWarning"]


class RigsimError(Exception):
    """Base of every error the ``rigsim`` command reports as one line (exit 2)."""


class CliError(RigsimError, ValueError):
    """Bad command-line input: the message names the option, the value and the allowed range."""


class RigError(RigsimError, ValueError):
    """A rig file is unreadable or invalid. ``str(err)`` is the user-facing message."""

    def __init__(self, path, problems: list[str]):
        self.path = str(path)
        self.problems = list(problems)
        head = f"{self.path}: invalid rig file"
        if len(self.problems) == 1:
            msg = f"{head}: {self.problems[0]}"
        else:
            msg = head + f" ({len(self.problems)} problems):\n" + "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(msg)


class GeometryError(RigsimError, ValueError):
    """A geometry that cannot work (no turntable pose brings a face normal onto the beam, …)."""


class SearchError(RigsimError, RuntimeError):
    """A null search cannot proceed (no measurable spot, or it does not converge)."""


class InputError(RigsimError, ValueError):
    """A user's file (frame, table, JSON result) is unreadable or holds a wrong column, unit, shape,
    bit depth or value: the message names the file, the line/column and what was expected."""


POOR_FIT_EXIT = 3  # the exit status of a command whose data do not fit its model


class PoorFitError(RigsimError):
    """The data do not fit the estimator's model by a wide margin (docs/fit-judgement.md): nothing was
    written as a result. The message names the χ²/dof and the causes that make the data fit, if any;
    ``rigsim`` exits with :data:`POOR_FIT_EXIT`."""

    exit_status = POOR_FIT_EXIT


class DatasetError(RigsimError):
    """A dataset folder, its manifest or a prediction file is unusable."""


class ViewError(RigsimError, ValueError):
    """A 3D view cannot be built or written (bad pose, face, size or output path)."""


class ResourceError(RigsimError):
    """A run that cannot fit in the machine's memory or on the output disk (known before it starts)."""


class ExportError(RigsimError, ValueError):
    """A scene cannot be exported as plain Mitsuba XML."""


class GeometryWarning(UserWarning):
    """Geometry that cannot give a valid measurement (spot off the detector, cut, too big, …)."""


class SaturationWarning(UserWarning):
    """A frame has saturated pixels (full well or ADC top code)."""
