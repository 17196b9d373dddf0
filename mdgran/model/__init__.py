"""The model: units and scales (``units``), the contact laws (each law's arithmetic once in
``contact_scalar``, lifted over arrays in ``contact``), unlike beads (``mixture``), excitations
(``drive``), scene files and their typed section records (``scene``, ``scene_records``), and
the chain's forces, energies and ledger (``chain``).

The model imports only the package's base modules; the backends, the output and the studies
build on it.
"""
