"""The review page: one self-contained HTML file to check a landmark association."""
