"""python -m hybrid.docgen"""

import sys

from . import main

if __name__ == "__main__":  # not when a tool imports every module (tests/test_kernel_docs.py)
    sys.exit(main())
