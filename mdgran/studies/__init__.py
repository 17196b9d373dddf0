"""The studies: parameter sweeps (``sweep``, with the sweep files of ``mdgran/sweeps/``), the
paper's study behind ``mdgran report`` (``paper_study``) with its controls (``controls``) and
figures (``paper_figures``), and long chains (``long_chain``).

The studies run scenes through the driver and read the runs back with the output and the
analysis; only the cross-checks, the API and the command line build on them.
"""
