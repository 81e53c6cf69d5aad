"""``python -m kinecal`` runs the command-line interface."""

from kinecal._entry import run

run()
