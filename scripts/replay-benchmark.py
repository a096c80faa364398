#!/usr/bin/env python3
"""python-can + cantools on a candump log: the reference of scripts/replay-benchmark.

    python3 scripts/replay-benchmark.py DBC LOG

Reads LOG with python-can's CanutilsLogReader and decodes every frame of the catalogue
with cantools (`Database.decode_message`), as an engineer's script would; prints one line:
frames, seconds, frames per second, peak resident memory.
"""

import resource
import sys
import time

import can
import cantools


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    db = cantools.database.load_file(sys.argv[1])
    known = {m.frame_id for m in db.messages if not m.name.startswith(("Diag", "Obd"))}
    started = time.perf_counter()
    frames = decoded = 0
    for msg in can.CanutilsLogReader(sys.argv[2]):
        frames += 1
        if msg.arbitration_id in known:
            db.decode_message(msg.arbitration_id, msg.data)
            decoded += 1
    seconds = time.perf_counter() - started
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"python-can + cantools: {frames} frames ({decoded} decoded) in {seconds:.2f} s = "
          f"{frames / seconds:.0f} frames/s, peak RSS {peak_kb} kB")


if __name__ == "__main__":
    main()
