"""The report of ``slamrel run``: the page, its verdict, comparison tables."""
