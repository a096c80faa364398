#!/usr/bin/env python3
"""asammdf on an MF4 bus log: the reference of scripts/mf4-benchmark.

    python3 scripts/mf4-benchmark.py DBC FILE.mf4

Opens FILE with asammdf and decodes its CAN bus logging against DBC with
`MDF.extract_bus_logging`, as an engineer's script would; prints one line: frames (the
CAN_DataFrame records), seconds, frames per second, signals extracted, peak resident memory.
"""

import resource
import sys
import time

from asammdf import MDF


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    dbc, path = sys.argv[1], sys.argv[2]
    started = time.perf_counter()
    mdf = MDF(path)
    frames = sum(g.channel_group.cycles_nr for g in mdf.groups
                 if g.channel_group.acq_name == "CAN"
                 and any(c.name == "CAN_DataFrame" for c in g.channels))
    decoded = mdf.extract_bus_logging({"CAN": [(dbc, 0)]})
    signals = sum(len(g.channels) for g in decoded.groups)
    seconds = time.perf_counter() - started
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"asammdf extract_bus_logging: {frames} frames ({signals} channels) in {seconds:.2f} s"
          f" = {frames / seconds:.0f} frames/s, peak RSS {peak_kb} kB")


if __name__ == "__main__":
    main()
