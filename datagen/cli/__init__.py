"""The ``datagen`` command line.

Bad input ends with one line per problem on stderr and exit status 2, and so
does a file that cannot be read or written (read-only folder, full disk, a name
too long); no traceback reaches the user for anything that is not a bug in
datagen. Every count a flag takes has an upper bound, checked before any work.
"""

from datagen.cli import assets, commands  # noqa: F401 (each registers its commands on the app)
from datagen.cli.common import app, main

__all__ = ["app", "main"]
