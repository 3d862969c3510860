"""The one registry of user actions: every menu item, its shortcut and what runs it.

The main window's menus and context menus, ``carapost shortcuts`` and the tests
are all generated from :data:`ACTIONS`; nothing else lists menu items or
shortcuts.  Titles and shortcuts are the Reference Guide's menu tables.  An item
carapost cannot offer (Check For Updates: there is no update service) has
``available=False`` and a tooltip saying why: the window shows it disabled, never
as a silent no-op.

This module is Qt-free: shortcuts are Qt "portable text" strings
(``"Ctrl+Shift+H"``), handlers are dotted names resolved by the GUI.
"""
from __future__ import annotations

from dataclasses import dataclass

#: When an action is enabled (besides ``available``); the GUI evaluates these names.
ENABLE_CONDITIONS = ("always", "project", "undo", "redo", "history", "recent", "brim")

#: Top-level menus in menu-bar order.
MENUS = ("File", "Edit", "View", "Process", "Help")

#: The context menu of a camera view (guide: "2D context menus").
CONTEXT_2D = "2D"
#: The context menus of the 3D view, the Graph view and the Continuity chart.
CONTEXT_3D = "3D"
CONTEXT_GRAPH = "Graph"
CONTEXT_CONTINUITY = "Continuity"
#: Every view's context menu (their items are not in the menu bar).
CONTEXT_MENUS = (CONTEXT_2D, CONTEXT_3D, CONTEXT_GRAPH, CONTEXT_CONTINUITY)
#: The Tracker pane's buttons and the keyframe nudges: window shortcuts, not menu items.
TRACKER_PANE = "Tracker pane"


@dataclass(frozen=True)
class Action:
    """One user action.

    Attributes
    ----------
    id : str
        Stable identifier, e.g. ``"edit.merge"``.
    menu : str
        Menu path, ``"Edit"`` or ``"View > Panels"``; one of :data:`CONTEXT_MENUS`
        for a view's context menu.
    title : str
        The guide's menu text.
    shortcut : str
        Qt portable-text key sequence, ``""`` for none.
    handler : str
        ``"<controller>.<method>"`` on the main window (``""``: none yet).
    enabled_when : str
        One of :data:`ENABLE_CONDITIONS`.
    tooltip : str
        What it does (for unavailable items: why it is disabled).
    available : bool
        False until the operation exists; the item is then shown disabled.
    checkable : bool
        A toggle (Full Screen, display options...).
    arg : str
        Passed to the handler (one handler serves several toggles).
    separator_before : bool
        Draw a separator above the item.
    while_busy : bool
        May run while a background job runs (navigation, display); edits may not.
    mnemonic : str
        The Alt letter; empty to pick one automatically (see :func:`menu_text`).
    """

    id: str
    menu: str
    title: str
    shortcut: str = ""
    handler: str = ""
    enabled_when: str = "project"
    tooltip: str = ""
    available: bool = True
    checkable: bool = False
    arg: str = ""
    separator_before: bool = False
    while_busy: bool = False
    mnemonic: str = ""

    @property
    def top_menu(self) -> str:
        """The menu-bar menu the item lives under (``"Process"`` for ``"Process > ROM Tools"``)."""
        return self.menu.split(" > ")[0]


_A = Action
ACTIONS: tuple[Action, ...] = (
    # ------------------------------------------------------------------ File
    _A("file.open", "File", "Open", "Ctrl+O", "files.open", "always", "Open a .cara project.", while_busy=False),
    _A("file.clear", "File", "Clear", "", "files.clear", "project", "Close the current project."),
    _A("file.save", "File", "Save", "Ctrl+S", "files.save", "project",
       "Save the project (asks for a name when it has none)."),
    _A("file.save_as", "File", "Save As", "", "files.save_as", "project", "Save the project to a file you name."),
    _A("file.import_pico", "File", "Import Pico Files", "", "files.import_pico", "always",
       "Start a new project from the .pico files of a take (one per channel).", separator_before=True),
    _A("file.import_brim_svg", "File", "Import Calibration Brim [svg]", "", "files.import_brim_svg", "project",
       "Use a custom calibration brim: every circle of the SVG is a marker (mm)."),
    _A("file.import_xcp", "File", "Import XCP", "", "files.import_xcp", "project",
       "Set the cameras from an .xcp calibration file."),
    _A("file.import_labels_cara", "File", "Import Labels From Cara File", "", "files.import_labels_cara", "project",
       "Add the labels of another .cara project to the label list."),
    _A("file.import_labels_text", "File", "Import Labels From Text File", "", "files.import_labels_text", "project",
       "Add labels from a text file; names already present get ' - Copy' appended."),
    _A("file.export_xcp", "File", "Export XCP [Current Frame]", "", "files.export_xcp", "project",
       "Write the cameras of the current frame to an .xcp file.", separator_before=True),
    _A("file.export_c3d", "File", "Export C3D", "", "files.export_c3d", "project",
       "Write the points to a .c3d file (see the Export properties)."),
    _A("file.export_fbx", "File", "Export FBX", "", "files.export_fbx", "project",
       "Write the points to an .fbx file: one animated Null per point (see the Export properties)."),
    # Recent Files is a submenu of the last eight projects, rebuilt by the window.
    _A("file.clear_recent", "File", "Clear Recent Files", "", "files.clear_recent", "recent",
       "Empty the Recent Files list.", separator_before=True, while_busy=True),
    _A("file.exit", "File", "Exit", "", "files.exit", "always", "Close carapost.", separator_before=True,
       mnemonic="x"),
    # ------------------------------------------------------------------ Edit
    _A("edit.undo", "Edit", "Undo", "Ctrl+Z", "edit.undo", "undo", "Undo the last action."),
    _A("edit.redo", "Edit", "Redo", "Ctrl+Y", "edit.redo", "redo", "Redo the last undone action."),
    _A("edit.clear_history", "Edit", "Clear History", "", "edit.clear_history", "history",
       "Forget the undo history to free memory."),
    _A("edit.create_points", "Edit", "Create Points From Detections", "", "edit.create_points_from_detections",
       "project", "A new point for each selected detection.", separator_before=True),
    _A("edit.delete_selected", "Edit", "Delete Selected", "Ctrl+D", "edit.delete_selected", "project",
       "Delete the selected points (whole take) or detections."),
    _A("edit.split_point", "Edit", "Split Selected Point", "", "edit.split_point", "project",
       "From the current frame on, move the selected point's data to a new point."),
    _A("edit.merge", "Edit", "Merge", "M", "edit.merge", "project",
       "Merge the selected points and detections into one point on the current frame."),
    _A("edit.merge_next_label", "Edit", "Merge and Select Next Label", "L", "edit.merge_and_select_next_label",
       "project", "Merge, give the point the label selected in the Labelling pane, then select the next label."),
    _A("edit.clear_selected_frame", "Edit", "Clear Selected [Current Frame]", "", "edit.clear_selected",
       "project", "Remove the selected points' data on the current frame (detections stay).", arg="frame"),
    _A("edit.clear_selected_range", "Edit", "Clear Selected [Active Range]", "", "edit.clear_selected",
       "project", "Remove the selected points' data in the active range (detections stay).", arg="range"),
    _A("edit.detach_frame", "Edit", "Detach Detections [Current Frame]", "Ctrl+H", "edit.detach_detections",
       "project", "Detach the selected points' 2D data in the active or selected channels, current frame.",
       arg="frame"),
    _A("edit.detach_range", "Edit", "Detach Detections [Active Range]", "Ctrl+Shift+H", "edit.detach_detections",
       "project", "Detach the selected points' 2D data in the active or selected channels, active range.",
       arg="range"),
    _A("edit.relocate_files", "Edit", "Relocate Files", "", "files.relocate", "project",
       "Choose where each channel's media is.", separator_before=True),
    _A("edit.increment_offset", "Edit", "Increment Image Sequence Offset", "", "edit.increment_image_offset",
       "project", "Move the selected channels' video one frame forward."),
    _A("edit.add_target_track", "Edit", "Add Target Track", "Shift+A", "edit.set_click_mode", "project",
       "Click in a camera view to create a point with a target-track keyframe there.", arg="add",
       separator_before=True),
    _A("edit.edit_target_track", "Edit", "Edit Target Track", "Shift+E", "edit.set_click_mode", "project",
       "Click in a camera view to put a keyframe of the selected point there.", arg="edit"),
    _A("edit.stop_point_edit", "Edit", "Stop Point Edit mode", "Shift+S", "edit.set_click_mode", "project",
       "Leave Add/Edit Target Track mode.", arg=""),
    _A("edit.gaps_to_keys", "Edit", "Gaps To Keys", "", "target.gaps_to_keys", "project",
       "With a point selected, add keyframes on both sides of every gap in its tracking."),
    _A("edit.remove_unused_detections", "Edit", "Remove Unused Detections", "", "edit.remove_unused_detections",
       "project", "Delete every detection not attached to a point, on every frame."),
    _A("edit.remove_interpolated", "Edit", "Remove Interpolated 3D Points", "", "edit.remove_interpolated",
       "project", "Remove interpolated 3D data of the selected (or all) points in the active range."),
    _A("edit.rename_point", "Edit", "Rename Point", "Ctrl+R", "edit.rename_point", "project",
       "Change the label of the selected point.", separator_before=True),
    _A("edit.clear_all_labels", "Edit", "Clear All Labels", "", "edit.clear_all_labels", "project",
       "Empty the label list and unlabel every point."),
    _A("edit.delete_selected_labels", "Edit", "Delete Selected Labels", "", "edit.delete_selected_labels",
       "project", "Remove the labels selected in the Labelling pane."),
    _A("edit.unlabel", "Edit", "Unlabel Selected Points", "Ctrl+U", "edit.unlabel", "project",
       "Remove the labels of the selected points."),
    _A("edit.create_stick", "Edit", "Create Stick from Selected Point", "S", "edit.create_stick", "project",
       "With two points selected, a stick between them.", separator_before=True),
    _A("edit.create_stick_mesh", "Edit", "Create Stick Mesh", "", "edit.create_stick_mesh", "project",
       "A triangle mesh of sticks over the face points with 3D data on this frame."),
    _A("edit.edit_stick_color", "Edit", "Edit Stick Color", "", "edit.edit_stick_color", "project",
       "Change the colour of the selected sticks (of all sticks when none is selected)."),
    _A("edit.clear_active_range", "Edit", "Clear Active Range", "", "edit.clear_active_range", "project",
       "Detach every point's data in the active range (detections stay).", separator_before=True),
    _A("edit.restore_defaults", "Edit", "Restore Properties To Defaults", "", "edit.restore_defaults", "project",
       "Reset every property to its default."),
    _A("edit.read_blob_parameters", "Edit", "Read Blob Parameters From Pico Files", "", "edit.read_blob_parameters",
       "project", "Set the Blob Parameters back to those stored in the imported .pico files."),
    # ------------------------------------------------------------------ View
    # View > Panels items are built from the docks (one per pane), see PANELS.
    _A("view.new_workspace", "View", "New Floating Workspace", "", "views.new_workspace", "project",
       "A floating window with the workspace's views (the 3D view first).", separator_before=True,
       while_busy=True),
    _A("view.show_brim_svg", "View", "Show Calibration Brim SVG", "", "views.show_brim_svg", "brim",
       "Show the calibration brim (its SVG, or the default brim's layout), numbered; click a marker to attach "
       "the detections selected in the camera views to it.", while_busy=True),
    _A("view.full_screen", "View", "Full Screen", "F", "views.full_screen", "always",
       "Fill the screen with the window.", checkable=True, while_busy=True),
    _A("view.toggle_docks", "View", "Toggle Dock Widget Visibility", "Ctrl+F", "views.toggle_docks", "always",
       "Hide or show every pane, leaving the views and timebar.", while_busy=True),
    _A("view.blob_preview", "View", "Toggle Blob Preview", "Ctrl+B", "views.toggle_display", "always",
       "Show the blobs Detect Blobs would find with the current Blob Parameters.", checkable=True,
       arg="blob_preview", while_busy=True),
    _A("view.show_stabilized", "View", "Toggle Show Stabilized", "Ctrl+Shift+S", "stabilize.toggle_show", "project",
       "Show the stabilised (and aligned) positions instead of the raw ones in the 3D view.", checkable=True,
       while_busy=True),
    _A("view.go_to_frame", "View", "Go To Frame", "Ctrl+G", "navigate.go_to_frame", "project",
       "Go to a frame by number.", separator_before=True, while_busy=True),
    _A("view.go_start", "View", "Go to Start Frame", "Home", "navigate.go_start", "project",
       "Go to the first frame of the view range.", while_busy=True),
    _A("view.go_end", "View", "Go to End Frame", "End", "navigate.go_end", "project",
       "Go to the last frame of the view range.", while_busy=True),
    _A("view.play", "View", "Play", "Space", "navigate.play", "project",
       "Play or stop (plays every frame).", checkable=True, while_busy=True),
    _A("view.next_frame", "View", "Next Frame", "Right", "navigate.step", "project",
       "Next frame; held down, plays.", arg="1", while_busy=True),
    _A("view.prev_frame", "View", "Prev Frame", "Left", "navigate.step", "project",
       "Previous frame; held down, plays backwards.", arg="-1", while_busy=True),
    _A("view.lock_to_point", "View", "Lock To Point", "", "views.lock_to_point", "project",
       "Keep the selected points at the centre of the views while playing.", checkable=True, while_busy=True),
    _A("view.next_keyframe", "View", "Next Key Frame", "Shift+Right", "navigate.keyframe", "project",
       "Next target-track keyframe of the selected point (else the next frame).", arg="1", while_busy=True),
    _A("view.prev_keyframe", "View", "Prev Key Frame", "Shift+Left", "navigate.keyframe", "project",
       "Previous target-track keyframe of the selected point (else the previous frame).", arg="-1",
       while_busy=True),
    _A("view.select_point", "View", "Select Point", "Ctrl+P", "navigate.select_point", "project",
       "Select a point by its id (or label).", separator_before=True, while_busy=True),
    _A("view.point_information", "View", "Get Point Information", "", "views.point_information", "project",
       "Write the selected point's 3D position, size per sensor and camera distances to the log.",
       while_busy=True),
    _A("view.rotate_cw", "View", "Rotate Selected Sensors Clockwise", "Ctrl+Right", "views.rotate", "project",
       "Rotate the selected channels' video 90 degrees clockwise (saved in the project).", arg="1"),
    _A("view.rotate_ccw", "View", "Rotate Selected Sensors Anticlockwise", "Ctrl+Left", "views.rotate", "project",
       "Rotate the selected channels' video 90 degrees anticlockwise (saved in the project).", arg="-1"),
    _A("view.fewest_gaps", "View", "Select Point With Fewest Gaps", "Ctrl+A", "navigate.select_fewest_gaps",
       "project", "Select the point with the fewest gaps.", while_busy=True),
    _A("view.next_gap", "View", "Go To Next Gap of Selected Point", "", "navigate.next_gap", "project",
       "Go to the frame before the selected point's next gap.", while_busy=True),
    _A("view.distance", "View", "Distance Between Two Points", "", "views.distance", "project",
       "Write the 3D distance between the two selected points to the log.", while_busy=True),
    _A("view.next_label", "View", "Select Next Label", "K", "navigate.select_label", "project",
       "Select the next (missing) label in the Labelling pane.", arg="1", while_busy=True),
    _A("view.prev_label", "View", "Select Previous Label", "J", "navigate.select_label", "project",
       "Select the previous (missing) label in the Labelling pane.", arg="-1", while_busy=True),
    _A("view.active_start", "View", "Set Active Range Start", "Ctrl+1", "navigate.active_range", "project",
       "The active range starts at the current frame.", arg="start", separator_before=True),
    _A("view.active_end", "View", "Set Active Range End", "Ctrl+2", "navigate.active_range", "project",
       "The active range ends at the current frame.", arg="end"),
    _A("view.active_reset", "View", "Reset Active Range", "Ctrl+3", "navigate.active_range", "project",
       "The active range is the whole take.", arg="reset"),
    _A("view.view_to_active", "View", "Set View Range to Active Range", "", "navigate.view_range", "project",
       "The timebar shows the active range.", arg="active"),
    _A("view.view_reset", "View", "Reset View Range", "", "navigate.view_range", "project",
       "The timebar shows the whole take.", arg="reset"),
    # ------------------------------------------------------------------ Process
    # The guide lists Center/Frame Selection first under the Process menu heading.
    _A("process.center_selection", "Process", "Center Selection All 2D Views", "C", "views.center_selection",
       "project", "Centre the selected points in every camera view.", while_busy=True),
    _A("process.frame_selection", "Process", "Frame Selection All 2D Views", "Shift+C", "views.frame_selection",
       "project", "Zoom every camera view onto the selected points.", while_busy=True),
    _A("process.detect_blobs_range", "Process", "Detect Blobs [Active Range]", "", "process.detect_blobs", "project",
       "Find blobs on every frame of the active range with the Blob Parameters (in the background).", arg="range",
       separator_before=True),
    _A("process.detect_blobs_frame", "Process", "Detect Blobs [Current Frame]", "", "process.detect_blobs",
       "project", "Find blobs on the current frame with the Blob Parameters.", arg="frame"),
    _A("process.load_rom", "Process", "Load ROM", "", "rom.load_rom", "project",
       "Load the .cara of a ROM take of the same actor and marker set, to initialise this take from.",
       separator_before=True),
    _A("process.init_from_rom", "Process", "Initialize from ROM", "", "rom.initialize", "project",
       "Initialise the current frame from the loaded ROM: cameras, brim, labelled face points and sticks "
       "(see the Initialize From ROM Parameters).", arg="full"),
    _A("process.init_from_rom_brim", "Process", "Initialize from ROM [Brim Only]", "", "rom.initialize", "project",
       "Initialise the brim points and the cameras of the current frame from the loaded ROM.", arg="brim"),
    _A("process.rom_timebar", "Process > ROM Tools", "Display ROM Timebar", "", "rom.show_timebar", "project",
       "A timebar of the ROM take in its own window: it sets the ROM Frame Index."),
    _A("process.rom_add_2d", "Process > ROM Tools", "Add 2D To ROM Correspondence", "Ctrl+L", "rom.add_correspondence",
       "project", "The selected ROM point (click a pale blue ROM point) is the selected detection."),
    _A("process.rom_clear_2d", "Process > ROM Tools", "Clear 2D To ROM Correspondence", "",
       "rom.clear_correspondences", "project", "Forget every 2D to ROM correspondence."),
    _A("process.rom_solve_camera", "Process > ROM Tools", "Solve ROM Camera From Correspondences", "",
       "rom.solve_camera", "project",
       "Solve the camera of the channel with 4+ correspondences; the ROM's rig follows it."),
    _A("process.rom_solve_face", "Process > ROM Tools", "Solve ROM Face Alignment From Correspondences", "",
       "rom.solve_face", "project", "Move the ROM face rigidly onto the face correspondences of every channel."),
    _A("process.brim_v20", "Process", "Initialize Default Calibration Brim [v2.0]", "", "process.default_brim",
       "project", "Use the v2.0 calibration brim.", arg="v2.0", separator_before=True),
    _A("process.brim_v11", "Process", "Initialize Default Calibration Brim [v1.1]", "", "process.default_brim",
       "project", "Use the v1.1 calibration brim.", arg="v1.1"),
    _A("process.brim_v10", "Process", "Initialize Default Calibration Brim [v1.0]", "", "process.default_brim",
       "project", "Use the v1.0 calibration brim.", arg="v1.0"),
    _A("process.solve_brim", "Process", "Solve Calibration Brim [Manual]", "", "process.solve_brim", "project",
       "Solve the cameras of the current frame from the brim points you attached; sets the calibration pose."),
    _A("process.initialize_3d", "Process", "Initialize 3D", "", "process.initialize_3d", "project",
       "Grow 3D face points from the seed points on the current frame and solve its cameras.",
       separator_before=True),
    _A("process.bundle_frame", "Process", "Bundle Current Frame [Unconstrained]", "", "process.bundle_frame",
       "project", "Bundle-adjust the cameras and points of the current frame."),
    _A("process.bundle_sequence", "Process", "Bundle Sequence [Unconstrained]", "", "process.bundle_sequence",
       "project", "Bundle-adjust every frame of the active range on its own (in the background)."),
    _A("process.track_fwd_seq", "Process", "Track Forwards [Sequence]", "", "process.track", "project",
       "Track the selected (or all) points from the current frame to the end of the active range.",
       arg="forwards", separator_before=True),
    _A("process.track_back_seq", "Process", "Track Backwards [Sequence]", "", "process.track", "project",
       "Track the selected (or all) points from the current frame to the start of the active range.",
       arg="backwards"),
    _A("process.track_fwd_frame", "Process", "Track Forwards [Single Frame]", "Ctrl+W", "process.track",
       "project", "Track the selected (or all) points into the next frame and go there.", arg="forwards_frame"),
    _A("process.track_back_frame", "Process", "Track Backwards [Single Frame]", "", "process.track", "project",
       "Track the selected (or all) points into the previous frame and go there.", arg="backwards_frame"),
    _A("process.stabilize_manual", "Process", "Stabilize Data [Manual]", "", "stabilize.stabilize_manual", "project",
       "Map the selected stable points (3 or more, gap-free) of every active-range frame onto the current frame.",
       separator_before=True),
    _A("process.stabilize_assisted", "Process", "Stabilize Data [Assisted]", "", "stabilize.stabilize_assisted",
       "project", "Stabilise the active range onto the current frame from the selected points and the most stable "
       "others (see the Stabilization properties; in the background)."),
    _A("process.align", "Process", "Align Data", "", "stabilize.align", "project",
       "Three selected points define the frame: the first the origin, the second the X axis, the third the XY "
       "plane."),
    _A("process.interpolate", "Process", "Interpolate Gaps", "", "process.interpolate_gaps", "project",
       "Fill the gaps of the selected (or all) points in the active range (see the Gap-Filling properties).",
       separator_before=True),
    # ------------------------------------------------------------------ Help
    _A("help.online", "Help", "View latest help on vicon.com", "", "helpmenu.online", "always",
       "Open Vicon's CaraPost documentation page in a browser.", while_busy=True),
    _A("help.installed", "Help", "View installed help", "", "helpmenu.installed", "always",
       "Open carapost's user guide (docs/gui.md).", while_busy=True),
    Action("help.updates", "Help", "Check For Updates", "", "", "always",
           "Not available: carapost has no update service; upgrade with pip.", available=False),
    _A("help.licensing", "Help", "Licensing", "", "helpmenu.licensing", "always",
       "carapost's licence (MIT; no licence server).", while_busy=True),
    _A("help.third_party", "Help", "Show 3rd Party Licenses", "", "helpmenu.third_party", "always",
       "The licences of the libraries carapost uses.", while_busy=True),
    _A("help.about", "Help", "About", "", "helpmenu.about", "always", "Version and copyright.", while_busy=True),
    # ------------------------------------------------------------- 2D context menu
    _A("view2d.fit", CONTEXT_2D, "Fit To Window", "", "view2d.fit", "project",
       "Fit the whole image into the view.", while_busy=True),
    _A("view2d.actual_size", CONTEXT_2D, "Actual Size", "", "view2d.actual_size", "project",
       "One image pixel per screen pixel.", while_busy=True),
    _A("view2d.start_measurement", CONTEXT_2D, "Start Measurement", "", "view2d.start_measurement", "project",
       "Drag a line to read its length in pixels.", separator_before=True, while_busy=True),
    _A("view2d.clear_measurement", CONTEXT_2D, "Clear Measurement", "", "view2d.clear_measurement", "project",
       "Remove the measurement line.", while_busy=True),
    _A("view2d.center_selection", CONTEXT_2D, "Center Selection", "", "view2d.center_selection", "project",
       "Centre the selection in this view.", separator_before=True, while_busy=True),
    _A("view2d.frame_selection", CONTEXT_2D, "Frame Selection", "", "view2d.frame_selection", "project",
       "Zoom this view onto the selection.", while_busy=True),
    _A("view2d.border", CONTEXT_2D, "Border", "", "views.toggle_display", "always",
       "Without the image, a checkerboard instead of grey.", checkable=True, arg="border",
       separator_before=True, while_busy=True),
    _A("view2d.image", CONTEXT_2D, "Image", "", "views.toggle_display", "always",
       "Draw the video (clear it for faster scrubbing).", checkable=True, arg="image", while_busy=True),
    _A("view2d.detections", CONTEXT_2D, "Detections", "", "views.toggle_display", "always",
       "Draw detections (red ellipses).", checkable=True, arg="detections", while_busy=True),
    _A("view2d.points", CONTEXT_2D, "Points", "", "views.toggle_display", "always",
       "Draw points (blue rings).", checkable=True, arg="points", while_busy=True),
    _A("view2d.projections", CONTEXT_2D, "Projections", "", "views.toggle_display", "always",
       "Draw projections of 3D points.", checkable=True, arg="projections", while_busy=True),
    _A("view2d.connected", CONTEXT_2D, "Connected", "", "views.toggle_display", "always",
       "Draw connected projections (yellow cross in a circle).", checkable=True, arg="connected",
       while_busy=True),
    _A("view2d.unconnected", CONTEXT_2D, "Unconnected", "", "views.toggle_display", "always",
       "Draw unconnected projections (orange x in a circle).", checkable=True, arg="unconnected",
       while_busy=True),
    _A("view2d.errors", CONTEXT_2D, "Errors", "", "views.toggle_display", "always",
       "Draw reprojection errors (yellow lines).", checkable=True, arg="errors", while_busy=True),
    _A("view2d.blob_preview", CONTEXT_2D, "Blob Preview", "", "views.toggle_display", "always",
       "Preview Detect Blobs with the current Blob Parameters.", checkable=True, arg="blob_preview",
       while_busy=True),
    _A("view2d.pixel_report", CONTEXT_2D, "Pixel Report", "", "views.toggle_display", "always",
       "Show x, y and grey level under the mouse.", checkable=True, arg="pixel_report", while_busy=True),
    _A("view2d.rom", CONTEXT_2D, "ROM", "", "rom.toggle_display", "always",
       "Draw the loaded ROM's points (pale blue) where the ROM cameras see them; click one to select it.",
       checkable=True, while_busy=True),
    _A("view2d.sticks", CONTEXT_2D, "Sticks", "", "views.toggle_display", "always",
       "Draw sticks.", checkable=True, arg="sticks", while_busy=True),
    _A("view2d.labels_all", CONTEXT_2D, "Point Labels: All", "", "views.toggle_labels_all", "project",
       "Show every point label (the Display property Point Labels : All).", checkable=True),
    # ------------------------------------------------------------- Tracker pane (the Target Tracker)
    _A("tracker.back_to_start", TRACKER_PANE, "Track back to start", "", "target.track", "project",
       "Track the selected points back to the start of the active range (or until a stop setting ends it).",
       arg="back_to_start", while_busy=True),
    _A("tracker.back_one", TRACKER_PANE, "Track back one frame", "", "target.track", "project",
       "Track the selected points back one frame and go there.", arg="back_one"),
    _A("tracker.forward_one", TRACKER_PANE, "Track forward one frame", "", "target.track", "project",
       "Track the selected points forward one frame and go there.", arg="forward_one"),
    _A("tracker.forward_to_end", TRACKER_PANE, "Track forward to end", "", "target.track", "project",
       "Track the selected points to the end of the active range (or until a stop setting ends it).",
       arg="forward_to_end", while_busy=True),
    _A("tracker.clear", TRACKER_PANE, "Clear Tracked Points", "", "target.clear_tracked", "project",
       "Delete the selected points' target-tracked 2D samples and keyframes in the active range."),
    _A("tracker.add_keyframe", TRACKER_PANE, "Add Keyframe To Current Frame", "", "target.add_keyframe", "project",
       "Key the selected points' 2D samples on this frame (every channel that has one)."),
    _A("tracker.nudge_left", TRACKER_PANE, "Nudge Keyframe Left", "Ctrl+Shift+Left", "target.nudge", "project",
       "Move the selected point's keyframe one pixel left in the active (or selected) view.", arg="left"),
    _A("tracker.nudge_right", TRACKER_PANE, "Nudge Keyframe Right", "Ctrl+Shift+Right", "target.nudge", "project",
       "Move the selected point's keyframe one pixel right in the active (or selected) view.", arg="right"),
    _A("tracker.nudge_up", TRACKER_PANE, "Nudge Keyframe Up", "Ctrl+Shift+Up", "target.nudge", "project",
       "Move the selected point's keyframe one pixel up in the active (or selected) view.", arg="up"),
    _A("tracker.nudge_down", TRACKER_PANE, "Nudge Keyframe Down", "Ctrl+Shift+Down", "target.nudge", "project",
       "Move the selected point's keyframe one pixel down in the active (or selected) view.", arg="down"),
    # ------------------------------------------------------------- 3D context menu
    _A("view3d.fit_to_points", CONTEXT_3D, "Fit To Points", "", "viewctx.fit_to_points", "project",
       "Move the 3D view to fit the selected points (all points when none is selected).", while_busy=True),
    _A("view3d.center_selection", CONTEXT_3D, "Center Selection", "", "viewctx.center_selection", "project",
       "Turn about the selection's centre and put it in the middle of the 3D view.", while_busy=True),
    _A("view3d.frame_selection", CONTEXT_3D, "Frame Selection", "", "viewctx.frame_selection", "project",
       "Centre and zoom the 3D view onto the selection.", while_busy=True),
    _A("view3d.face_points", CONTEXT_3D, "Face Points", "", "views.toggle_display", "always",
       "Draw the face points.", checkable=True, arg="face_points", separator_before=True, while_busy=True),
    _A("view3d.brim_points", CONTEXT_3D, "Calibration Brim Points", "", "views.toggle_display", "always",
       "Draw the calibration brim points (green).", checkable=True, arg="brim_points", while_busy=True),
    _A("view3d.reconstruction_colors", CONTEXT_3D, "Reconstruction Type Colors", "", "views.toggle_display",
       "always", "Colour face points by how they were reconstructed: yellow from matched detections, orange "
       "with patch-matched data, red fully predicted or interpolated (cleared: all yellow).", checkable=True,
       arg="reconstruction_colors", while_busy=True),
    _A("view3d.cameras", CONTEXT_3D, "Cameras", "", "views.toggle_display", "always",
       "Draw the cameras of the current frame.", checkable=True, arg="cameras", while_busy=True),
    _A("view3d.rays", CONTEXT_3D, "Rays", "", "views.toggle_display", "always",
       "Draw lines from the selected points to the cameras whose 2D data they use.", checkable=True, arg="rays",
       while_busy=True),
    _A("view3d.rom", CONTEXT_3D, "ROM", "", "views.toggle_display", "always",
       "Draw the points of the loaded ROM's frame as pale blue dots (nothing when no ROM is loaded).",
       checkable=True, arg="rom_3d", while_busy=True),
    _A("view3d.sticks", CONTEXT_3D, "Sticks", "", "views.toggle_display", "always",
       "Draw the sticks (and the stick mesh).", checkable=True, arg="sticks_3d", while_busy=True),
    _A("view3d.labels_all", CONTEXT_3D, "Point Labels: All", "", "views.toggle_labels_all", "project",
       "Show every point label (the Display property Point Labels : All).", checkable=True),
    # ---------------------------------------------------------- Graph context menu
    _A("graph.fit_to_data", CONTEXT_GRAPH, "Fit To Data", "", "viewctx.graph_fit_to_data", "project",
       "Zoom to the data of the selected points (nothing selected: no change).", while_busy=True),
    _A("graph.track_data", CONTEXT_GRAPH, "Track Data", "", "viewctx.graph_track_data", "project",
       "Show the 2D image x and y of the selected points in the graph's sensor.", checkable=True,
       while_busy=True),
    _A("graph.recon_data", CONTEXT_GRAPH, "Recon Data", "", "viewctx.graph_recon_data", "project",
       "Show the 3D x, y and z (mm) of the selected points (red x, green y, blue z).", checkable=True,
       while_busy=True),
    # ----------------------------------------------------- Continuity context menu
    _A("continuity.collapse_all", CONTEXT_CONTINUITY, "Collapse All", "", "viewctx.continuity_collapse_all",
       "project", "Show one bar per point, no channel rows.", while_busy=True),
    _A("continuity.expand_all", CONTEXT_CONTINUITY, "Expand All", "", "viewctx.continuity_expand_all",
       "project", "Show the channel rows of every point.", while_busy=True),
    _A("continuity.fit_to_data", CONTEXT_CONTINUITY, "Fit To Data", "", "viewctx.continuity_fit_to_data",
       "project", "Show the selected points (all points when none is selected).", while_busy=True),
)
del _A

#: The panes of View > Panels, in the guide's order: (dock object name, title).
PANELS: tuple[tuple[str, str], ...] = (
    ("labelling", "Labelling"), ("history", "History"), ("selected_point", "Selected Point"), ("log", "Log"),
    ("properties", "Properties"), ("selection", "Selection"), ("tracker", "Tracker"),
)

_BY_ID = {a.id: a for a in ACTIONS}
assert len(_BY_ID) == len(ACTIONS), "duplicate action id"
assert all(a.enabled_when in ENABLE_CONDITIONS for a in ACTIONS)
assert all(a.top_menu in MENUS or a.menu in CONTEXT_MENUS or a.menu == TRACKER_PANE for a in ACTIONS)


def action(action_id: str) -> Action:
    """The action with this id (KeyError when unknown)."""
    return _BY_ID[action_id]


def menu_actions(menu: str) -> list[Action]:
    """Actions of one menu path, in order (``"Edit"``, ``"Process > ROM Tools"``, one of :data:`CONTEXT_MENUS`)."""
    return [a for a in ACTIONS if a.menu == menu]


def shortcut_table() -> list[dict]:
    """``[{"menu", "action", "shortcut"}]`` of every menu-bar action of the registry (no window needed)."""
    return [{"menu": a.top_menu, "action": a.title, "shortcut": a.shortcut}
            for a in ACTIONS if a.menu not in CONTEXT_MENUS]


def mnemonic_titles(titles: list[str], fixed: dict[int, str] | None = None) -> list[str]:
    """Menu texts with an ``&`` before a letter unique within the menu (Alt+letter).

    Parameters
    ----------
    titles : list of str
        Item titles of one menu, in order.
    fixed : dict, optional
        Index -> letter chosen by hand (e.g. ``x`` for Exit).

    Returns
    -------
    list of str
        Titles with one ``&`` each where a free letter exists: word initials
        first, then any letter; ``&`` already in a title is escaped.
    """
    fixed = fixed or {}
    taken = {c.lower() for c in fixed.values()}
    out = []
    for i, title in enumerate(titles):
        text = title.replace("&", "&&")
        want = fixed.get(i)
        pos = -1
        if want:
            pos = text.lower().find(want.lower())
        else:
            initials = [j for j, c in enumerate(text) if c.isalnum() and (j == 0 or text[j - 1] in " [(")]
            rest = [j for j, c in enumerate(text) if c.isalnum()]
            for j in initials + rest:
                if text[j].lower() not in taken:
                    pos = j
                    break
        if pos >= 0:
            taken.add(text[pos].lower())
            text = text[:pos] + "&" + text[pos:]
        out.append(text)
    return out
