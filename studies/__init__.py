"""The project's own studies of the method, apart from the product (``pipeline``).

What a user of the method runs is the product: sources, simulation, odometry, tuning, metrics,
the database, descriptors, surrogates, the artifact, the runtime and the stages. The studies
ask how well the method does and why: the one suite runner (``suites``: settings over a suite
of worlds or recorded runs), the toy's generalization suite, the coverage model's verdict, the
paper's KITTI protocol (``kitti``), the sim-to-real comparison (``realism``) and the docs pages
generated from their committed metrics (``docs``). Studies import the product; the product
never imports a study (tests/test_imports.py). Their commands are ``adaptune study ...``.
"""
