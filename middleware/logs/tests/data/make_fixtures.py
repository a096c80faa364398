#!/usr/bin/env python3
"""Writes the python-can fixtures of autoplug-logs' tests (tests/fixtures.rs).

The same eight messages, in every format python-can writes, so the Rust readers are
checked against files written by another implementation:

  python-can.log          can.CanutilsLogWriter (candump, with python-can's R/T suffix)
  python-can.asc          can.ASCWriter
  python-can.blf          can.BLFWriter, zlib-compressed containers
  python-can-stored.blf   can.BLFWriter, compression_level=0 (stored containers)
  python-can-split.blf    can.BLFWriter, 64-byte containers: objects cut across containers
  python-can.mf4          can.MF4Writer (asammdf underneath: MDF 4.10 bus logging, a
                          compressed data block), written only where asammdf is installed
  asammdf-plain.mf4       python-can.mf4 saved again by asammdf: plain ##DT blocks,
  asammdf-deflate.mf4     ##DZ deflate blocks,
  asammdf-transposed.mf4  ##DZ transposed deflate blocks

Run from anywhere: python3 middleware/logs/tests/data/make_fixtures.py (python-can 4.x).
The files are committed; rerun only when MESSAGES changes, then update tests/fixtures.rs.
ASCWriter dates its header with the time of the run, so python-can.asc changes then.
"""

import pathlib

import can

HERE = pathlib.Path(__file__).resolve().parent
T0 = 1_700_000_000.0  # 2023-11-14 22:13:20 UTC

MESSAGES = [
    # 1. standard data frame
    can.Message(timestamp=T0, arbitration_id=0x00C, is_extended_id=False,
                data=[0x0A, 0x14, 0x1E, 0x28], channel=0),
    # 2. no data
    can.Message(timestamp=T0 + 0.001234, arbitration_id=0x7FF, is_extended_id=False,
                data=[], channel=0),
    # 3. extended, 8 bytes, transmitted, second channel
    can.Message(timestamp=T0 + 0.012345, arbitration_id=0x1ABCDEF0, is_extended_id=True,
                data=[1, 2, 3, 4, 5, 6, 7, 8], is_rx=False, channel=1),
    # 4. remote frame, DLC 4
    can.Message(timestamp=T0 + 0.1, arbitration_id=0x123, is_extended_id=False,
                is_remote_frame=True, dlc=4, channel=0),
    # 5. error frame
    can.Message(timestamp=T0 + 0.2, is_error_frame=True, channel=0),
    # 6. CAN FD, 12 bytes
    can.Message(timestamp=T0 + 0.3, arbitration_id=0x456, is_extended_id=False, is_fd=True,
                data=list(range(12)), channel=0),
    # 7. a frame of the AutoPlug catalogue (VehicleSpeedMsg, 100 km/h)
    can.Message(timestamp=T0 + 0.400001, arbitration_id=0x003, is_extended_id=False,
                data=[0x64], channel=0),
    # 8. extended identifier below 0x800, transmitted
    can.Message(timestamp=T0 + 1.5, arbitration_id=0x123, is_extended_id=True,
                data=[0xFF], is_rx=False, channel=0),
]


def write(writer):
    for message in MESSAGES:
        writer.on_message_received(message)
    writer.stop()


def main():
    write(can.CanutilsLogWriter(HERE / "python-can.log"))
    write(can.ASCWriter(HERE / "python-can.asc"))
    write(can.BLFWriter(HERE / "python-can.blf"))
    write(can.BLFWriter(HERE / "python-can-stored.blf", compression_level=0))
    write(can.BLFWriter(HERE / "python-can-split.blf", max_container_size=64))
    names = ["python-can.log", "python-can.asc", "python-can.blf",
             "python-can-stored.blf", "python-can-split.blf"]
    try:
        write(can.MF4Writer(HERE / "python-can.mf4"))
        names.append("python-can.mf4")
        from asammdf import MDF
        for compression, name in [(0, "plain"), (1, "deflate"), (2, "transposed")]:
            path = HERE / f"asammdf-{name}.mf4"
            MDF(HERE / "python-can.mf4").save(path, overwrite=True, compression=compression)
            names.append(path.name)
    except ImportError as e:  # python-can's MF4Writer needs asammdf
        print(f"python-can.mf4 not written: {e}")
    for name in names:
        print(f"{name}: {(HERE / name).stat().st_size} bytes")


if __name__ == "__main__":
    main()
