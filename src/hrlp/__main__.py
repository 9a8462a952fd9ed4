"""``python -m hrlp`` and the ``hrlp`` console script.

The stop signals' handlers (:mod:`hrlp.stopping`) are installed before the command's modules are imported, so that a
Ctrl-C while they import (torch takes seconds) ends in one line, not a traceback.
"""

import sys

from hrlp.stopping import as_stop, exit_at_once_on_stop_signals, install_stop_handlers


def main() -> None:
    """Run the ``hrlp`` command; a stop signal at any moment ends it with one line and exit code 128 + the signal."""
    install_stop_handlers()
    try:
        from hrlp.cli import main as cli_main

        cli_main()
    except BaseException as error:  # a stop before the command started (its own stops are reported by hrlp.cli)
        if (stop := as_stop(error)) is None:
            raise
        print(stop.line("during start-up; nothing was written"), file=sys.stderr, flush=True)
        raise SystemExit(stop.exit_code) from None
    finally:
        exit_at_once_on_stop_signals()


if __name__ == "__main__":
    main()
