"""View menu display handlers, the views' context-menu items, and the Help menu."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from PySide6.QtCore import Qt, QUrl
from PySide6.QtGui import QDesktopServices
from PySide6.QtWidgets import QDockWidget, QVBoxLayout, QWidget

from ..core.edits import RotateSensors, SetProperties
from .cameraview import CameraView

log = logging.getLogger("carapost")


def selection_xy(session, view: CameraView) -> np.ndarray:
    """Raw positions in ``view``'s sensor of the selected points and detections (for centring)."""
    fd = session.frame_data()
    p, s, f = session.project, view.sensor, session.frame
    xy = fd.position_2d(s)
    rows = [r for r in (fd.row_of(pid) for pid in session.selection.points) if r >= 0]
    out = [xy[r] for r in rows]
    rec = p.detections[s].frame(f)
    out += [(float(rec["x"][i]), float(rec["y"][i])) for (ds, df, i) in session.selection.detections
            if ds == s and df == f and i < len(rec)]
    return np.array(out, float).reshape(-1, 2)


class ViewActions:
    """Handlers of the View menu's display items and of Center/Frame Selection All 2D Views."""

    def __init__(self, window):
        self.w = window
        self.locked = False
        self._hidden_docks: list[QDockWidget] = []
        self.workspaces: list[QWidget] = []
        #: the view grids of the floating workspaces
        self.grids: list = []
        #: View > Show Calibration Brim SVG's window, made when first shown
        self.brim_window = None

    @property
    def s(self):
        return self.w.session

    def toggle_display(self, name: str) -> None:
        """A display switch of every camera view (Image, Detections, Blob Preview...)."""
        on = not getattr(self.s.display, name)
        self.s.set_display(name, on)
        self.w.settings.setValue(f"display/{name}", on)
        if name == "blob_preview":
            log.info(f"Blob preview {'on' if on else 'off'}")

    def toggle_labels_all(self) -> None:
        p = self.s.project
        cmd = SetProperties({"display.point_labels_all": not p.properties["display.point_labels_all"]})
        self.s.run(cmd)

    def full_screen(self) -> None:
        """Full Screen (F)."""
        if self.w.isFullScreen():
            self.w.showNormal()
        else:
            self.w.showFullScreen()
        self.w.actionset.sync_checks()

    def toggle_docks(self) -> None:
        """Toggle Dock Widget Visibility (Ctrl+F): hide every pane, or bring back those hidden."""
        docks = list(self.w.docks.values())
        shown = [d for d in docks if d.isVisible()]
        if shown:
            self._hidden_docks = shown
            for d in shown:
                d.hide()
        else:
            for d in self._hidden_docks or docks:
                d.show()
            self._hidden_docks = []

    def lock_to_point(self) -> None:
        """Lock To Point: keep the selected points centred while playing."""
        self.locked = not self.locked
        self.w.actionset.sync_checks()
        if self.locked:
            self.center_selection(quiet=True)

    def on_frame(self) -> None:
        if self.locked:
            self.center_selection(quiet=True)

    def rotate(self, steps: str) -> None:
        """Rotate Selected Sensors (Ctrl+Right / Ctrl+Left): saved in the project."""
        sensors = self.s.project.selected_channels(self.s.active_sensor)
        cmd = RotateSensors(sensors, int(steps))
        cmd.summary = f"{cmd.name}: channel(s) {', '.join(map(str, sensors))}"
        self.s.run(cmd)

    def center_selection(self, quiet: bool = False) -> None:
        """Center Selection All 2D Views (C)."""
        done = [v.center_on(selection_xy(self.s, v)) for v in self.w.grid.visible_views()]
        if not any(done) and not quiet:
            log.info("Center Selection: nothing selected to centre on")

    def frame_selection(self) -> None:
        """Frame Selection All 2D Views (Shift+C)."""
        done = [v.frame_on(selection_xy(self.s, v)) for v in self.w.grid.visible_views()]
        if not any(done):
            log.info("Frame Selection: nothing selected to frame")

    # ------------------------------------------------------------- point read-outs (to the Log)
    def point_information(self) -> None:
        """Get Point Information: each selected point's 3D position, 2D data and sizes, camera distances."""
        from ..core.calib.pointinfo import format_point_information, point_information

        pts = self.s.selection.points
        if not pts:
            self.s.error("Get Point Information needs a point selected")
            return
        for pid in pts:
            for line in format_point_information(point_information(self.s.project, pid, self.s.frame)).splitlines():
                log.info(line)

    def distance(self) -> None:
        """Distance Between Two Points: the 3D distance of the two selected points on the current frame."""
        from ..core.calib.pointinfo import distance_between_points
        from ..core.errors import CaraError

        pts = self.s.selection.points
        if len(pts) != 2:
            self.s.error(f"Distance Between Two Points needs two points selected ({len(pts)} are)")
            return
        try:
            d = distance_between_points(self.s.project, pts[0], pts[1], self.s.frame)
        except CaraError as e:
            self.s.error(f"Distance Between Two Points: {e}")
            return
        labels = [self.s.project.point(i).label for i in pts]
        named = f" ({' and '.join(lb or 'unlabelled' for lb in labels)})" if any(labels) else ""
        log.info(f"Distance between points {pts[0]} and {pts[1]}{named} on frame {d['frame']}: "
                 f"{d['distance']:.3f} {d['units']}")

    def new_workspace(self) -> QWidget:
        """New Floating Workspace: another window with the workspace's views, showing the 3D view first."""
        from .viewgrid import ViewGrid

        win = QWidget(None)
        win.setWindowTitle(f"carapost workspace {len(self.workspaces) + 1}")
        # closed for good: its views stop listening to the session and free their memory
        win.setAttribute(Qt.WidgetAttribute.WA_DeleteOnClose, True)
        grid = ViewGrid(self.s, self.w.actionset.actions, win)
        win.destroyed.connect(lambda *_a, w=win, g=grid: self._forget_workspace(w, g))
        grid.on_document()
        grid.set_layout("1")
        grid.set_slot_kind(0, "3d")
        grid.sensorClicked.connect(self.w.edit.sensor_click)
        grid.targetClicked.connect(self.w.edit.target_click)
        lay = QVBoxLayout(win)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addWidget(grid)
        # the window's shortcuts (Merge, frame steps...) work in the workspace too
        win.addActions([a for a in self.w.actions()])
        win.resize(900, 600)
        win.show()
        self.workspaces.append(win)
        self.grids.append(grid)
        log.info(f"Opened floating workspace {len(self.workspaces)}")
        return win

    def _forget_workspace(self, win, grid) -> None:
        if win in self.workspaces:
            self.workspaces.remove(win)
        if grid in self.grids:
            self.grids.remove(grid)

    def show_brim_svg(self) -> None:
        """Show Calibration Brim SVG: the Brim window, where clicking a marker attaches the selected detections."""
        from .brim_window import BrimWindow

        if self.brim_window is None:
            self.brim_window = BrimWindow(self.s, self.w)
            # the window's shortcuts (Undo, frame steps...) work while the user clicks markers
            self.brim_window.addActions(self.w.actions())
        self.brim_window.show()
        self.brim_window.raise_()


def context_grid(window):
    """The view grid (main or floating workspace) whose context menu was opened last."""
    return max([window.grid] + window.views.grids, key=lambda g: g.menu_serial)


class ContextActions:
    """The 2D context menu's view items, acting on the view right-clicked."""

    def __init__(self, window):
        self.w = window

    def _view(self) -> CameraView | None:
        return context_grid(self.w).target_view()

    def fit(self) -> None:
        if v := self._view():
            v.fit()

    def actual_size(self) -> None:
        if v := self._view():
            v.actual_size()

    def start_measurement(self) -> None:
        if v := self._view():
            v.start_measurement()

    def clear_measurement(self) -> None:
        if v := self._view():
            v.clear_measurement()

    def center_selection(self) -> None:
        if v := self._view():
            v.center_on(selection_xy(self.w.session, v))

    def frame_selection(self) -> None:
        if v := self._view():
            v.frame_on(selection_xy(self.w.session, v))


class ViewContextActions:
    """The 3D, Graph and Continuity context menus' items, acting on the view right-clicked."""

    def __init__(self, window):
        self.w = window

    def _target(self, kind: str):
        return context_grid(self.w).context_target(kind)

    def _nothing(self, what: str) -> None:
        log.info(f"{what}: nothing selected")

    # ---------------------------------------------------------------- 3D
    def fit_to_points(self) -> None:
        if v := self._target("3d"):
            v.fit_to_points()

    def center_selection(self) -> None:
        if (v := self._target("3d")) and not v.center_selection():
            self._nothing("Center Selection")

    def frame_selection(self) -> None:
        if (v := self._target("3d")) and not v.frame_selection():
            self._nothing("Frame Selection")

    # ------------------------------------------------------------- Graph
    def graph_fit_to_data(self) -> None:
        if v := self._target("graph"):
            v.fit_to_data()

    def graph_track_data(self) -> None:
        if v := self._target("graph"):
            v.set_track_data(not v.track_data)

    def graph_recon_data(self) -> None:
        if v := self._target("graph"):
            v.set_recon_data(not v.recon_data)

    # -------------------------------------------------------- Continuity
    def continuity_collapse_all(self) -> None:
        if v := self._target("continuity"):
            v.collapse_all()

    def continuity_expand_all(self) -> None:
        if v := self._target("continuity"):
            v.expand_all()

    def continuity_fit_to_data(self) -> None:
        if v := self._target("continuity"):
            v.fit_to_data()


THIRD_PARTY = ("PySide6-Essentials (LGPL-3.0)", "shiboken6 (LGPL-3.0)", "pyqtgraph (MIT)", "numpy (BSD-3-Clause)",
               "scipy (BSD-3-Clause)", "opencv-python-headless (Apache-2.0)", "av / PyAV (BSD-3-Clause; FFmpeg LGPL)",
               "lxml (BSD-3-Clause)", "ezc3d (MIT)", "moderngl (MIT)", "dask / distributed (BSD-3-Clause)")


class HelpActions:
    """Handlers of the Help menu."""

    def __init__(self, window):
        self.w = window

    def online(self) -> None:
        QDesktopServices.openUrl(QUrl("https://docs.vicon.com/display/CaraPost"))

    def installed(self) -> None:
        doc = Path(__file__).resolve().parents[2] / "docs" / "gui.md"
        if doc.exists():
            QDesktopServices.openUrl(QUrl.fromLocalFile(str(doc)))
        else:
            self.w.prompts.info("Help", "The user guide (docs/gui.md) is not installed with this copy.")

    def licensing(self) -> None:
        self.w.prompts.info("Licensing", "carapost is free software under the MIT licence.\n"
                                         "It needs no licence server.")

    def third_party(self) -> None:
        self.w.prompts.info("3rd Party Licenses", "carapost uses:\n" + "\n".join(f"  {t}" for t in THIRD_PARTY))

    def about(self) -> None:
        from .. import __version__

        self.w.prompts.info("About carapost", f"carapost {__version__}\n"
                                              "An open-source re-creation of Vicon CaraPost.\nMIT licence.")
