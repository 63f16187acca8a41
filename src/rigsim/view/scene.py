"""The data a rig view is made of: meshes with their style, labels, beam paths and viewpoints.

A scene builder (one per rig family, :mod:`rigsim.view.registry`) turns a rig description into a
:class:`RigScene`. Nothing here opens a window: :mod:`rigsim.view.plot` puts a scene on a
``pyvista.Plotter`` (one or more viewports), and the same scene feeds the screenshot, the
interactive window and the file exports.

Coordinates are millimetres in the rig's lab frame (cube rigs: the turntable's rot frame, +Z′
towards the sun simulator / autocollimator; other families say which frame in
``RigScene.frame``). Beam polylines keep the analytic trace's float64 points unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rigsim.errors import ViewError

__all__ = ["Item", "Label", "Beam", "ViewSpec", "RigScene", "ALL_VIEWS", "COLOURS", "ViewError"]

ALL_VIEWS = ("*",)
"""``Item.views`` value: shown in every viewport."""


def _pose_text(pose) -> str:
    if isinstance(pose, dict):
        return ",".join(f"{k}={v}" for k, v in pose.items())
    return repr(pose)


# Okabe–Ito colour-blind-safe palette for the roles that matter; RGB for the frame axes.
COLOURS = {
    "incident": "#E69F00",      # orange: light on its way to the mirror
    "reflected": "#CC0066",     # crimson: light after the mirror
    "axis_x": "#D62728",
    "axis_y": "#2CA02C",
    "axis_z": "#1F77B4",
    "turntable": "#7F7F7F",
    "turntable_axis": "#404040",
    "sensor": "#3A3A3A",
    "cube": "#C8D7E6",
    "screen": "#F2EFE6",
    "simulator": "#F5D76E",
    "camera": "#56B4E9",
    "autocollimator": "#009E73",
    "mirror": "#B8C9D9",
    "star": "#E69F00",
    "frustum": "#56B4E9",
    "text": "#202020",
}


@dataclass
class Item:
    """One mesh of the scene.

    ``style`` holds keyword arguments of ``pyvista.Plotter.add_mesh`` (colour, opacity,
    line_width, …). ``views`` lists the viewports that show it (``("*",)``: all).
    ``legend`` puts an entry with this text and the item's colour in the overview's legend.
    """

    name: str
    mesh: Any
    style: dict = field(default_factory=dict)
    views: tuple[str, ...] = ALL_VIEWS
    group: str = ""
    legend: str | None = None
    on_top: bool = False

    def shown_in(self, view: str) -> bool:
        return "*" in self.views or view in self.views


@dataclass
class Label:
    """A text label anchored at a 3D point (mm), drawn always on top."""

    text: str
    point: np.ndarray
    views: tuple[str, ...] = ALL_VIEWS
    font_size: int = 13
    colour: str = COLOURS["text"]

    def shown_in(self, view: str) -> bool:
        return "*" in self.views or view in self.views


@dataclass
class Beam:
    """A ray path of the analytic model: ``points`` (n, 3) in mm, exactly as traced.

    ``role`` is ``"incident"`` or ``"reflected"`` (colour and legend); ``radius_mm`` is the true
    radius of the pencil it stands for (drawn as a tube of that radius in close-ups; 0: a ray);
    ``source`` names the function whose points these are.
    """

    name: str
    points: np.ndarray
    role: str
    radius_mm: float
    source: str
    description: str = ""


@dataclass
class ViewSpec:
    """A viewport: the camera looks at ``focus`` from the unit direction ``direction`` (from the
    focus towards the eye) with ``up``; ``extent_mm`` is the size of the region that must fit
    (the larger of its width and height). ``parallel``: orthographic projection."""

    name: str
    title: str
    focus: np.ndarray
    direction: np.ndarray
    up: np.ndarray
    extent_mm: float
    parallel: bool = False
    view_angle_deg: float = 30.0
    scale_bar_mm: float | None = None
    eye_distance_mm: float | None = None  # parallel views: where the eye sits (items behind it are not drawn)
    depth_mm: float | None = None  # draw only a slab of ± this depth about the focus (None: everything)


@dataclass
class RigScene:
    """Everything one rig view shows. ``views[0]`` is the overview."""

    rig_name: str
    family: str
    title: str
    frame: str
    items: list[Item] = field(default_factory=list)
    labels: list[Label] = field(default_factory=list)
    beams: list[Beam] = field(default_factory=list)
    views: list[ViewSpec] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    pose_deg: dict[str, float] = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    # -- access ------------------------------------------------------------------------------
    def item(self, name: str) -> Item:
        for it in self.items:
            if it.name == name:
                return it
        raise KeyError(f"no item {name!r}; items: {[i.name for i in self.items]}")

    def beam(self, name: str) -> Beam:
        for b in self.beams:
            if b.name == name:
                return b
        raise KeyError(f"no beam {name!r}; beams: {[b.name for b in self.beams]}")

    def view(self, name: str) -> ViewSpec:
        for v in self.views:
            if v.name == name:
                return v
        raise KeyError(f"no view {name!r}; views: {[v.name for v in self.views]}")

    @property
    def item_names(self) -> list[str]:
        return [i.name for i in self.items]

    @property
    def groups(self) -> set[str]:
        return {i.group for i in self.items}

    def bounds(self, view: str) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) corners of the axis-aligned box around the items shown in ``view``."""
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for it in self.items:
            if it.shown_in(view) and it.mesh.n_points:
                b = np.asarray(it.mesh.bounds, float).reshape(3, 2)
                lo = np.minimum(lo, b[:, 0])
                hi = np.maximum(hi, b[:, 1])
        return lo, hi

    def points(self, view: str, max_points: int = 50000) -> np.ndarray:
        """Mesh points of the items shown in ``view`` (subsampled to about ``max_points``)."""
        parts = [np.asarray(it.mesh.points, float) for it in self.items if it.shown_in(view) and it.mesh.n_points]
        pts = np.vstack(parts)
        step = max(1, len(pts) // max_points)
        return pts[::step]

    # -- building ----------------------------------------------------------------------------
    def add(self, name: str, mesh, *, group: str, views=ALL_VIEWS, legend: str | None = None, **style) -> Item:
        if any(i.name == name for i in self.items):
            raise ValueError(f"duplicate scene item {name!r}")
        it = Item(name, mesh, style, tuple(views), group, legend)
        self.items.append(it)
        return it

    def label(self, text: str, point, views=ALL_VIEWS, font_size: int = 13, colour: str = COLOURS["text"]) -> None:
        self.labels.append(Label(text, np.asarray(point, float), tuple(views), font_size, colour))

    def add_beam(self, beam: Beam, *, line_width: float = 7.0, tube_views=(), line_views=ALL_VIEWS,
                 legend: str | None = None, colour: str | None = None) -> None:
        """Register a traced beam: a polyline item ``beam:<name>`` (the exact points) and, for
        ``tube_views``, a tube ``beam:<name>:tube`` of the pencil's true radius."""
        from rigsim.view import primitives as P

        self.beams.append(beam)
        col = colour or COLOURS.get(beam.role, "#000000")
        # a reflected ray runs within arcseconds of its incident ray: drawn thinner and on top
        refl = beam.role == "reflected"
        it = self.add(f"beam:{beam.name}", P.polyline(beam.points), group="beam", views=line_views, legend=legend,
                      color=col, line_width=0.4 * line_width if refl else line_width,
                      render_lines_as_tubes=not refl, lighting=False)
        it.on_top = refl
        if tube_views and beam.radius_mm > 0:
            self.add(f"beam:{beam.name}:tube", P.tube(beam.points, beam.radius_mm), group="beam",
                     views=tube_views, color=col, opacity=0.55, smooth_shading=True)
