"""mdgran: simulation of 1-D adhesive micro-granular chains (Schwarz contact, elastic substrate).

Everything inside the package is nondimensional (units of ``../shared/physics.md`` section 1):
force ``eta = pi R w``, length ``p``, time ``1/q``, bead mass 1.  SI input is converted once,
in :mod:`mdgran.units`.
"""
__version__ = "0.1.0"
