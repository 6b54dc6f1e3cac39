"""cosim: coupling manager, case loader, CLI and outputs of the FE-DE simulator."""
__version__ = "0.1.0"
