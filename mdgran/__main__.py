import sys

from .cli import main

if __name__ == "__main__":  # mpi4py.futures workers import the main module as __mp_main__
    sys.exit(main())
