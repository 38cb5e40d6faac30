"""``python -m debist``: the same command line as the ``debist`` script (:mod:`debist.cli`)."""

from debist.cli import main

main()
