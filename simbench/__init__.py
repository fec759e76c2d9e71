"""simbench: a physically based testbed for single-shot structured-light depth sensing."""

__version__ = "0.1.0"
