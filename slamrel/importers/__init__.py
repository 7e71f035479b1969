"""Importers of public datasets into slamrel's formats."""
