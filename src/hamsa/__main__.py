"""``python -m hamsa`` and the ``hamsa`` command: the command-line tool, started under its Ctrl-C handler."""

import os
import signal
import sys


def _on_interrupt(signum, frame) -> None:
    """Ctrl-C: a KeyboardInterrupt (the command cleans up and exits 130), except in the middle of an import,
    where an exception would leave modules half-initialized (Python may wrap it in another error): there the
    process says so, removes any temporary output and exits 130 at once."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            print("hamsa: interrupted", file=sys.stderr, flush=True)
            files = sys.modules.get("hamsa.files")
            if files is not None:
                files.remove_pending()
            os._exit(130)
        frame = frame.f_back
    raise KeyboardInterrupt


def run() -> int:
    """Import and run the command-line tool; Ctrl-C at any moment, start-up imports included, exits 130."""
    signal.signal(signal.SIGINT, _on_interrupt)
    try:
        from hamsa.cli import main

        return main()
    except KeyboardInterrupt:
        print("hamsa: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(run())
