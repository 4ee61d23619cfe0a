"""``python -m datagen``: the command line (:mod:`datagen.cli`)."""

from datagen.cli import main

main()
