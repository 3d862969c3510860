"""Up to four view slots with the layout buttons and the views' context menus.

Each slot shows a camera view (Sensor 0-3), the 3D view, the Graph view or the
Continuity chart; the View submenu of a slot's context menu switches it.
``views`` are always the slots' camera views (hidden while their slot shows
another kind).  The context menus' items come from the action registry
(:data:`~carapost.core.actions.CONTEXT_MENUS`); their handlers act on the view
last right-clicked (:meth:`ViewGrid.context_target`)."""
from __future__ import annotations

import itertools

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QAction, QActionGroup
from PySide6.QtWidgets import (QButtonGroup, QGridLayout, QHBoxLayout, QLabel, QMenu, QStackedWidget, QToolButton,
                               QVBoxLayout, QWidget)

from ..core.actions import CONTEXT_2D, CONTEXT_3D, CONTEXT_CONTINUITY, CONTEXT_GRAPH, menu_actions
from .cameraview import CameraView

#: name -> (tooltip, rows, columns); a layout button also restores every view's zoom.
LAYOUTS = {
    "1": ("One camera view", 1, 1),
    "2": ("Two camera views side by side", 1, 2),
    "2x2": ("Four camera views in a grid", 2, 2),
    "1x4": ("Four camera views in a row", 1, 4),
}
MAX_VIEWS = 4
#: What a slot can show.
SLOT_KINDS = ("sensor", "3d", "graph", "continuity")
#: The View submenu's entries besides the sensors: (title, kind).
VIEW_CHOICES = (("3D", "3d"), ("Graph", "graph"), ("Continuity", "continuity"))
#: The registry's context menu of each kind.
CONTEXT_OF = {"sensor": CONTEXT_2D, "3d": CONTEXT_3D, "graph": CONTEXT_GRAPH, "continuity": CONTEXT_CONTINUITY}
_menu_serial = itertools.count(1)


class ViewGrid(QWidget):
    """The workspace's camera views.

    Parameters
    ----------
    session : Session
    actions : dict, optional
        The window's QActions by registry id (the context menu shows the 2D ones).
    """

    sensorClicked = Signal(int, bool)
    targetClicked = Signal(int, float, float)

    def __init__(self, session, actions: dict | None = None, parent=None):
        super().__init__(parent)
        self.session = session
        self.actions = actions or {}
        self.layout_name = "2x2"
        self.context_view: CameraView | None = None
        #: the widget (of any kind) last right-clicked, and when (the newest grid's menu is the one in use)
        self.context_widget = None
        self.menu_serial = 0
        self.open_menu: QMenu | None = None
        bar = QHBoxLayout()
        bar.setContentsMargins(2, 0, 2, 0)
        bar.addWidget(QLabel("Views:"))
        self.buttons = QButtonGroup(self)
        for name, (tip, _r, _c) in LAYOUTS.items():
            b = QToolButton(text=name, checkable=True, toolTip=tip + " (restores zoom and scrolling)")
            b.clicked.connect(lambda _=False, n=name: self.set_layout(n))
            self.buttons.addButton(b)
            bar.addWidget(b)
        bar.addStretch(1)
        self.grid = QGridLayout()
        self.grid.setSpacing(2)
        self.grid.setContentsMargins(0, 0, 0, 0)
        self.views = [CameraView(session, i, self) for i in range(MAX_VIEWS)]
        self.slots = [QStackedWidget(self) for _ in range(MAX_VIEWS)]
        #: per slot: one of SLOT_KINDS
        self.kinds = ["sensor"] * MAX_VIEWS
        self._others: list[dict] = [{} for _ in range(MAX_VIEWS)]   # kind -> widget, made on first use
        for slot, v in zip(self.slots, self.views):
            slot.addWidget(v)
            v.contextRequested.connect(self.show_context_menu)
            v.sensorClicked.connect(self.sensorClicked)
            v.targetClicked.connect(self.targetClicked)
            # the click goes on to select: only the views' frames (which one is active) change here
            v.activated.connect(lambda _s: self.refresh_info())
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.setSpacing(2)
        lay.addLayout(bar)
        lay.addLayout(self.grid, 1)
        s = session
        s.documentChanged.connect(self.on_document)
        s.frameChanged.connect(self.on_frame)
        s.projectChanged.connect(self.refresh)
        s.displayChanged.connect(self.refresh)
        for sig in (s.selectionChanged, s.hoverChanged, s.modeChanged, s.labelChanged):
            sig.connect(self.refresh_selection)
        s.loader.imageReady.connect(self.on_image)
        self.set_layout(self.layout_name)

    # ---------------------------------------------------------------- layout
    def visible_views(self) -> list[CameraView]:
        return [v for v in self.views if v.isVisibleTo(self)]

    def set_layout(self, name: str) -> None:
        """Show the views of layout ``name`` and fit each to its window."""
        if name not in LAYOUTS:
            name = "2x2"
        self.layout_name = name
        _tip, rows, cols = LAYOUTS[name]
        n = rows * cols
        p = self.session.project
        if p is not None:
            n = min(n, p.sensor_count)
        for slot in self.slots:
            self.grid.removeWidget(slot)
            slot.hide()
        for i, slot in enumerate(self.slots[:n]):
            self.grid.addWidget(slot, i // cols, i % cols)
            slot.show()
        for b in self.buttons.buttons():
            b.setChecked(b.text() == name)
        for v in self.views[:n]:
            v.fit()

    # ------------------------------------------------------------ slot kinds
    def slot_of(self, widget) -> int:
        """Index of the slot showing (or holding) ``widget``; -1 when none."""
        for i, slot in enumerate(self.slots):
            if slot.indexOf(widget) >= 0:
                return i
        return -1

    def slot_widget(self, index: int):
        """What slot ``index`` shows: its CameraView, View3D, GraphView or ContinuityChart."""
        return self.slots[index].currentWidget()

    def set_slot_kind(self, index: int, kind: str, sensor: int | None = None) -> None:
        """Show ``kind`` (one of :data:`SLOT_KINDS`) in slot ``index`` (``sensor``: for "sensor")."""
        if kind not in SLOT_KINDS:
            raise ValueError(f"unknown view kind {kind!r}")
        slot, cam = self.slots[index], self.views[index]
        if kind == "sensor":
            if sensor is not None and sensor != cam.sensor:
                cam.set_sensor(sensor)
            w = cam
        else:
            w = self._others[index].get(kind)
            if w is None:
                if kind == "continuity":
                    from .continuity import ContinuityChart
                    w = ContinuityChart(self.session)
                elif kind == "3d":
                    from .view3d import View3D
                    w = View3D(self.session)
                else:
                    from .graphview import GraphView
                    w = GraphView(self.session, 0)       # the guide: a Graph view starts on Sensor 0
                w.contextRequested.connect(self.show_context_menu)
                self._others[index][kind] = w
                slot.addWidget(w)
        self.kinds[index] = kind
        slot.setCurrentWidget(w)
        if kind == "sensor":
            cam.refresh()
            cam.refresh_selection()
            cam.fit()

    def charts(self, kind: str) -> list:
        """The visible slots' widgets of ``kind`` ("3d", "graph" or "continuity")."""
        return [self.slot_widget(i) for i, s in enumerate(self.slots)
                if self.kinds[i] == kind and s.isVisibleTo(self)]

    def on_document(self) -> None:
        p = self.session.project
        for i, v in enumerate(self.views):
            v.set_sensor(i % p.sensor_count if p is not None else i)
        self.set_layout(self.layout_name)

    # ---------------------------------------------------------------- redraw
    # (session signals go to methods, not lambdas: Qt drops those connections when a workspace closes)
    def on_frame(self, _frame: int) -> None:
        self.refresh()

    def refresh(self) -> None:
        for v in self.visible_views():
            v.refresh()

    def refresh_selection(self) -> None:
        for v in self.visible_views():
            v.refresh_selection()

    def refresh_info(self) -> None:
        """The views' text and frame colour (active view, selected channels, mode)."""
        for v in self.visible_views():
            v.refresh_info()

    def on_image(self, sensor: int) -> None:
        for v in self.visible_views():
            if v.sensor == sensor:
                v.refresh_image()
                if self.session.display.blob_preview:
                    v.refresh_overlays()

    def view_of_sensor(self, sensor: int) -> CameraView | None:
        for v in self.visible_views():
            if v.sensor == sensor:
                return v
        return None

    # ------------------------------------------------------------ context menu
    def build_context_menu(self, view) -> QMenu:
        """The context menu of ``view``: the View submenu, then its kind's registry items (and Sensor)."""
        menu = QMenu(self)
        menu.setToolTipsVisible(True)
        p = self.session.project
        sensors = range(p.sensor_count) if p is not None else range(0)
        index = max(self.slot_of(view), 0)
        kind = self.kinds[index]
        cam = self.views[index]
        m_view = menu.addMenu("View")
        m_view.setToolTipsVisible(True)
        group = QActionGroup(m_view)
        choices = [(name, k, None) for name, k in VIEW_CHOICES] + [(f"Sensor {s}", "sensor", s) for s in sensors]
        for name, k, s in choices:
            on = kind == k and (s is None or s == cam.sensor)
            a = QAction(name, m_view, checkable=True, checked=on)
            a.setToolTip(f"Show {'the ' + name + ' view' if s is None else name} in this view")
            a.triggered.connect(lambda _=False, i=index, k=k, s=s: self.set_slot_kind(i, k, s))
            group.addAction(a)
            m_view.addAction(a)
        if kind == "sensor":
            self._sensor_menu(menu, sensors, view.sensor, view.set_sensor)
        if kind == "graph":     # each Graph view has its own Track / Recon Data switches
            for aid, on in (("graph.track_data", view.track_data), ("graph.recon_data", view.recon_data)):
                if aid in self.actions:
                    self.actions[aid].setChecked(on)
        for act in menu_actions(CONTEXT_OF[kind]):
            if act.separator_before:
                menu.addSeparator()
            qa = self.actions.get(act.id)
            if qa is not None:
                menu.addAction(qa)
        if kind == "graph":
            self._sensor_menu(menu, sensors, view.sensor, view.set_sensor)
        return menu

    @staticmethod
    def _sensor_menu(menu: QMenu, sensors, current: int, choose) -> None:
        m = menu.addMenu("Sensor")
        group = QActionGroup(m)
        for s in sensors:
            a = QAction(f"Sensor {s}", m, checkable=True, checked=(s == current))
            a.triggered.connect(lambda _=False, s=s: choose(s))
            group.addAction(a)
            m.addAction(a)

    def show_context_menu(self, view, pos) -> QMenu:
        """Open ``view``'s context menu at global ``pos`` (without blocking: it goes away when closed)."""
        self.note_context(view)
        if self.open_menu is not None:
            self.open_menu.close()
        menu = self.open_menu = self.build_context_menu(view)
        # an item's action runs before the menu is deleted: deleteLater waits for the event loop
        menu.aboutToHide.connect(menu.deleteLater)
        menu.destroyed.connect(lambda *_a: setattr(self, "open_menu", None))
        menu.popup(pos)
        return menu

    def note_context(self, view) -> None:
        """Remember ``view`` as the one the context menu's items act on."""
        if isinstance(view, CameraView):
            self.context_view = view
            self.session.set_active_sensor(view.sensor)
        self.context_widget = view
        self.menu_serial = next(_menu_serial)

    def target_view(self) -> CameraView | None:
        """The view a context-menu item acts on: the one right-clicked, else the active one."""
        if self.context_view is not None and self.context_view.isVisibleTo(self):
            return self.context_view
        return self.view_of_sensor(self.session.active_sensor) or (self.visible_views() or [None])[0]

    def context_target(self, kind: str):
        """The ``kind`` widget a context-menu item acts on: the one right-clicked, else the first shown."""
        w = self.context_widget
        if w is not None and w.isVisibleTo(self) and self.kinds[max(self.slot_of(w), 0)] == kind:
            return w
        shown = self.charts(kind)
        return shown[0] if shown else None

    def keyPressEvent(self, ev) -> None:  # Esc leaves Add/Edit Target Track mode
        if ev.key() == Qt.Key.Key_Escape and self.session.click_mode:
            self.session.set_click_mode("")
        else:
            super().keyPressEvent(ev)
