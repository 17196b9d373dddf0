"""The output: what a run leaves behind and how it is read back.  Writing files safely
(``storage``); checkpoints, and reading back the one a run resumes from (``checkpoint``); the
run record read back with its measures (``run_record``, ``measures``; ``trajectory`` is its
former name); progress lines (``progress``); the versions and MPI job a file records
(``run_environment``); the H5MD file's layout and appends (``h5md_layout``, ``h5md_append``)
and the writer (``h5md_writer``); the in-memory record (``memory_reporter``); the reporters'
names (``reporters``).

The output imports the model and the analysis; the driver hands it every block of a run.
"""
