"""calibctl: factory-line camera calibration with a versioned artifact store."""

__version__ = "0.1.0"
