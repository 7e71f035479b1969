"""The one simulator: seeded worlds, sensors and log bundles (a library; no CLI, no file I/O).

=================  ===========================================================================
``worlds``         geometry and named worlds: the drives of Hu, Huang & Dissanayake
                   (:data:`~slamrel.simulation.worlds.WORLDS`, ``PAPER_WORLDS``), features
                   around the path, noise types a/b/c, odometry or velocity controls;
                   :func:`~slamrel.simulation.worlds.make_world` gives a ``World``
``sensors``        the two range–bearing sensor models, named and explicit: a field-of-view
                   sensor (the worlds; polar or the paper's Cartesian noise) and an all-around
                   sensor (the test bundles); see the table in its docstring
``bundles``        log bundles: :func:`~slamrel.simulation.bundles.world_bundle` (a world as a
                   bundle with its true map) and :func:`~slamrel.simulation.bundles.
                   simulate_bundle` (the seeded unicycle bundle of the tests and benchmarks,
                   velocity or odometry model, optional map error and measurement offsets)
``example``        the reference/estimate pair and relations of ``slamrel example``
``relation_sets``  synthetic relation sets with planted gross errors (to measure a
                   relation check against the planted set)
=================  ===========================================================================

Everything is a pure function of its seed: the same arguments give the same numbers, bit
for bit. What is *not* simulation lives elsewhere: EKF-SLAM on a log
(:func:`slamrel.backends.ekf_slam.ekf_slam_bundle`), the file formats
(:mod:`recovery.bundle`, :mod:`slamrel.formats.trajectories`). Small files made from these
functions are in the project's top-level ``data/`` folder (``data/make_data.py``).

Import the submodules (``from slamrel.simulation.worlds import make_world``); this package
imports nothing, so importing one of them stays light.
"""
