"""``python -m guidefit`` runs the command line."""

from guidefit.cli import main

main()
