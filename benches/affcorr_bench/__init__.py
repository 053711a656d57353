"""affcorr's benchmarks and evaluation experiments, one module per experiment.

Run one as ``.venv/bin/python -m affcorr_bench.<module> [options]`` (benches/README.md lists
them). Importing a module does no work: every experiment runs from its ``main()``.

The package imports nothing itself, and ``affcorr_bench.common`` needs only numpy: the peer
workers (``affcorr_bench.peers.worker``) run in other virtualenvs that have neither affcorr nor
this package installed, with ``common.child_env()`` putting benches/ on their PYTHONPATH.
"""
