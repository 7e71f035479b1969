"""Reference relations from laser scans: alignment, global initialisation, proposals.

==================  =========================================================================
``matching``        point-to-line ICP (Censi 2008's metric) with trimmed, robustly weighted
                    correspondences; covariance, matched fraction, residual, degeneracy
``correlative``     multi-resolution correlative scan matching (Olson 2009): a global search
                    over a window when the initial guess is poor
``proposals``       which scan pairs to align: consecutive by travel, loops by proximity, or
                    the timestamp pairs of an existing relation file
``relations``       the pipeline (propose → initialise → align → judge) as typed results
``cycles``          the set-level check: each relation against the short cycles it closes
                    with the others (χ² of the composition), contradicted ones flagged
==================  =========================================================================

Pure maths (numpy/scipy), no file I/O and no CLI: the readers are in
:mod:`slamrel.formats.laser`, the command in :mod:`slamrel.commands.relations`.
"""
