"""The cross-checks: one scene on several backends against each other and the reference
(``compare``, behind ``mdgran compare``), and the report it writes (``compare_report``).

The cross-checks run scenes through the driver; only the API and the command line build on
them.
"""
