"""Former name of :mod:`mdgran.output.run_record`: ``Trajectory`` is
:class:`~mdgran.output.run_record.Run`.

Kept so that code written against mdgran 0.1 (``from mdgran.trajectory import Trajectory,
read_h5``, the old name of this module, :mod:`mdgran._moved`) keeps working; new code imports
from :mod:`mdgran.output.run_record`.
"""
from .run_record import LEDGER_NAMES, Run, read_h5  # noqa: F401

#: former name of :class:`~mdgran.output.run_record.Run`
Trajectory = Run
