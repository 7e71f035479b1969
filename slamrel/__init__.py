"""slamrel: the front door — CLI, pipelines, reports, importers, simulated worlds."""

__version__ = "0.1.0"
