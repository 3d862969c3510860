"""The main window: menus, camera views, timebar and panes around one Session.

The window owns no project state: the project, its history, selection and
current frame are the :class:`~carapost.core.document.Document`'s; the window
adapts it (:class:`~carapost.gui.session.Session`) and redraws when it changes.
Menus come from the action registry (:mod:`carapost.gui.menus`); handlers live
in small controllers (``files``, ``edit``, ``navigate``, ``views``, ``view2d``,
``process``, ``helpmenu``) the registry names.
"""
from __future__ import annotations

import logging
from pathlib import Path

from PySide6.QtCore import QByteArray, Qt
from PySide6.QtWidgets import QDockWidget, QMainWindow, QVBoxLayout, QWidget

from ..core.actions import PANELS
from . import qtfix
from .background import BackgroundRunner
from .edit_actions import EditActions
from .file_actions import FileActions
from .imageloader import ImageLoader
from .logpane import LogPane
from .menus import ActionSet
from .navigation import Navigation
from .panes.history import HistoryPane
from .panes.labelling import LabellingPane
from .panes.properties import PropertiesPane
from .panes.selected_point import SelectedPointPane
from .panes.selection import SelectionPane
from .panes.tracker import TrackerPane
from .process_actions import ProcessActions
from .prompts import Prompts
from .recovery import Recovery
from .rom_actions import RomActions
from .session import DisplayOptions, Session
from .settings import app_settings, read_bool
from .stabilize_actions import StabilizeActions
from .target_actions import TargetActions
from .timebar import TimePanel
from .view_actions import ContextActions, HelpActions, ViewActions, ViewContextActions
from .viewgrid import ViewGrid

log = logging.getLogger("carapost")

DEFAULT_SIZE = (1600, 1000)


class MainWindow(QMainWindow):
    """carapost's main window.

    Parameters
    ----------
    settings : QSettings, optional
        Where layout, display options and recent files persist (default: the user's).
    synchronous_images : bool
        Decode channel images in the GUI thread (screenshots, tests, benchmarks).
    autosave_s : float, optional
        Autosave interval in seconds (0: off; default: the ``autosave/interval_s`` setting).
    restore : bool
        Restore the saved window layout and display options.
    persist : bool
        Save them (and the recent files) when the window closes.
    """

    def __init__(self, settings=None, synchronous_images: bool = False, autosave_s: float | None = None,
                 restore: bool = True, persist: bool = True):
        qtfix.apply()         # before the thousands of Qt calls a session makes (PySide6 6.12 on Python 3.11)
        super().__init__()
        self.setObjectName("carapost_main")
        self.settings = settings if settings is not None else app_settings()
        self.persist = persist
        self.session = Session(ImageLoader(synchronous=synchronous_images), self)
        self.prompts = Prompts(self)
        # Controllers before the actions: enabled states and check marks read them.
        self.files = FileActions(self)
        self.edit = EditActions(self)
        self.navigate = Navigation(self)
        self.views = ViewActions(self)
        self.view2d = ContextActions(self)
        self.viewctx = ViewContextActions(self)
        self.helpmenu = HelpActions(self)
        self.process = ProcessActions(self)
        self.stabilize = StabilizeActions(self)
        self.rom = RomActions(self)
        self.target = TargetActions(self)
        self.actionset = ActionSet(self)
        actions = self.actionset.actions

        self.grid = ViewGrid(self.session, actions)
        self.time = TimePanel(self.session, actions)
        self.runner = BackgroundRunner(self.session, self.time.progress, self)
        central = QWidget()
        lay = QVBoxLayout(central)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.setSpacing(2)
        lay.addWidget(self.grid, 1)
        lay.addWidget(self.time)
        self.setCentralWidget(central)

        self.log_pane = LogPane()
        self.labelling = LabellingPane(self.session, self)
        self.history = HistoryPane(self.session, actions["edit.clear_history"])
        self.properties = PropertiesPane(self.session, actions["edit.restore_defaults"])
        self.selection_pane = SelectionPane(self.session)
        self.tracker = TrackerPane(self.session, actions)
        self.selected_point = SelectedPointPane(self.session)
        self.docks: dict[str, QDockWidget] = {}
        self._build_docks()
        self.actionset.build_menubar(self.menuBar(), [self.docks[name] for name, _t in PANELS])
        # Right-click on the menu bar lists the panes, to bring back a hidden one.
        bar = self.menuBar()
        bar.setContextMenuPolicy(Qt.ContextMenuPolicy.CustomContextMenu)
        bar.customContextMenuRequested.connect(lambda pos: self.createPopupMenu().exec(bar.mapToGlobal(pos)))
        self.recovery = Recovery(self, autosave_s)

        s = self.session
        s.errorRaised.connect(lambda msg: self.prompts.error("carapost", msg))
        for sig in (s.documentChanged, s.projectChanged, s.busyChanged):
            sig.connect(self._state_changed)
        s.displayChanged.connect(self.actionset.sync_checks)
        s.frameChanged.connect(lambda _f: self.views.on_frame())
        self.grid.sensorClicked.connect(self.edit.sensor_click)
        self.grid.targetClicked.connect(self.edit.target_click)
        self.time.timebar.frameRequested.connect(self.navigate.set_frame)
        self.time.timebar.activeRangeRequested.connect(self.navigate.set_active_range)
        self.resize(*DEFAULT_SIZE)
        if restore:
            self.restore_settings()
        self.update_title()

    # ------------------------------------------------------------------ layout
    def _build_docks(self) -> None:
        widgets = {"labelling": self.labelling, "history": self.history, "selected_point": self.selected_point,
                   "log": self.log_pane, "properties": self.properties, "selection": self.selection_pane,
                   "tracker": self.tracker}
        for name, title in PANELS:
            dock = QDockWidget(title, self)
            dock.setObjectName(f"dock_{name}")
            dock.setWidget(widgets[name])
            self.docks[name] = dock
        L, R, B = (Qt.DockWidgetArea.LeftDockWidgetArea, Qt.DockWidgetArea.RightDockWidgetArea,
                   Qt.DockWidgetArea.BottomDockWidgetArea)
        d = self.docks
        self.addDockWidget(L, d["labelling"])
        self.addDockWidget(L, d["selection"])
        self.addDockWidget(L, d["history"])
        self.addDockWidget(R, d["properties"])
        self.addDockWidget(R, d["tracker"])
        self.addDockWidget(B, d["log"])
        self.addDockWidget(B, d["selected_point"])
        self.splitDockWidget(d["log"], d["selected_point"], Qt.Orientation.Horizontal)
        self.resizeDocks([d["labelling"], d["properties"]], [230, 360], Qt.Orientation.Horizontal)
        self.resizeDocks([d["log"]], [150], Qt.Orientation.Vertical)

    def restore_settings(self) -> None:
        """Window geometry, dock state, view layout and display options of the last run."""
        st = self.settings
        geo, state = st.value("window/geometry"), st.value("window/state")
        if isinstance(geo, QByteArray):
            self.restoreGeometry(geo)
        if isinstance(state, QByteArray):
            self.restoreState(state)
        self.grid.set_layout(str(st.value("views/layout", self.grid.layout_name)))
        for name in DisplayOptions.names():
            self.session.set_display(name, read_bool(st, f"display/{name}", getattr(self.session.display, name)))

    def save_settings(self) -> None:
        st = self.settings
        st.setValue("window/geometry", self.saveGeometry())
        st.setValue("window/state", self.saveState())
        st.setValue("views/layout", self.grid.layout_name)
        for name in DisplayOptions.names():
            st.setValue(f"display/{name}", getattr(self.session.display, name))
        st.sync()

    # ------------------------------------------------------------------ state
    def _state_changed(self, *_args) -> None:
        self.actionset.update()
        self.update_title()

    def update_title(self) -> None:
        p = self.session.project
        if p is None:
            self.setWindowTitle("carapost")
            self.setWindowModified(False)
            return
        name = Path(p.path).name if p.path else (p.name or "untitled")
        self.setWindowTitle(f"{name}[*] — carapost")
        self.setWindowModified(self.session.is_modified())

    def action(self, action_id: str):
        """The QAction of registry id ``action_id``."""
        return self.actionset.actions[action_id]

    # ------------------------------------------------------------------ closing
    def closeEvent(self, ev) -> None:
        if self.runner.running:
            self.files.wait_for_background()
        if not self.files.maybe_save():
            ev.ignore()
            return
        self.navigate.stop()
        if self.persist:
            self.save_settings()
        self.recovery.clean_exit()
        self.log_pane.detach()
        self.session.loader.close_sources()
        for w in self.views.workspaces:
            w.close()
        ev.accept()
