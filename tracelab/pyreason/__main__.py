"""`python -m tracelab.pyreason SCRIPT.py [ARGS]`: run a PyReason script unchanged, its `import pyreason`
resolved to tracelab.pyreason for this run (as_pyreason.py); `tracelab run-pyreason` does the same. Not
through the CLI's parser: a script runs with only the imports it needs."""
import sys

from tracelab.errors import user_error_message

from .as_pyreason import run_script

if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
    print("usage: python -m tracelab.pyreason SCRIPT.py [ARGS ...]  (a PyReason script, run unchanged)",
          file=sys.stderr if len(sys.argv) < 2 else sys.stdout)
    sys.exit(2 if len(sys.argv) < 2 else 0)
try:
    run_script(sys.argv[1], sys.argv[2:])
except Exception as e:
    message = user_error_message(e)
    if message is None:
        raise  # the script's own error: its traceback, as python would show it
    print(f"tracelab: error: {message}", file=sys.stderr)
    sys.exit(1)
