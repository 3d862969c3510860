"""The window's panes (dock widgets): Labelling, History, Selected Point, Log, Properties, Selection, Tracker."""
