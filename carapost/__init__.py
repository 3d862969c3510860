"""carapost: an open-source re-creation of Vicon CaraPost."""

__version__ = "0.1.0"
