"""The package version, in a module of its own.

Core modules read it here without importing the package's public API (no import cycle).
"""

__version__ = "0.1.0"
