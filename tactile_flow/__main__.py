"""``python -m tactile_flow``: the version and the commands (``--version``: the version line only)."""

import sys

from tactile_flow import version_line

COMMANDS = """commands:
  tactile-run       run a protocol on the simulated or the real lab, record it, analyse it
  tactile-analyze   (re-)analyse recorded runs
  tactile-import    bring ROS bags or CSV files from elsewhere into run stores
  tactile-recover   close the store of a run that was killed
  tactile-emulate   the real lab's wire emulators, for a rehearsal
  tactile-view      a run in the Rerun viewer (pip install "tactile-flow[view]")
  tactile-demo      the method alone on a synthetic contact
Each command's --help says more."""


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    print(version_line())
    if "--version" not in argv:
        print(COMMANDS)
    return 0


if __name__ == "__main__":
    sys.exit(main())
