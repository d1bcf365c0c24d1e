"""`tracelab check`: verify every part of a run; with --repair, quarantine damaged ones (saying which
episodes they held) and clean up what a killed writer or a failed seal left behind."""
from __future__ import annotations

import argparse

from tracelab.errors import store_errors
from tracelab.store.check import check_run


def _size(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 100_000 else f"{n / 1e3:.1f} kB"


def run(args: argparse.Namespace) -> int:
    with store_errors():
        report = check_run(args.run, repair=args.repair)
    kind = "sealed file" if report.sealed else "parts"
    print(f"{report.run}: {report.parts} {'tables' if report.sealed else 'parts'} checked "
          f"({kind}), {report.rows:,} rows read")
    if report.error:
        print(f"damaged: the sealed file does not read: {report.error}")
        return 1
    for part in report.damaged:
        print(f"damaged: {part.path} ({part.table}; it held {part.episodes}): {part.error}")
    if report.quarantined:
        print(f"quarantined {len(report.quarantined)} part(s) in {report.run}/quarantine/ and took them "
              "out of the manifest; the rest of the run reads again")
    elif report.damaged:
        print(f"run `tracelab check {args.run} --repair` to quarantine them")
    if args.repair:
        print(f"removed {report.temps} temp file(s) and {_size(report.unlisted_bytes)} of parts the "
              "manifest no longer lists")
    if not report.damaged:
        print("ok")
    return 0 if report.ok else 1
