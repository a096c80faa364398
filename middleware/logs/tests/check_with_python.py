#!/usr/bin/env python3
"""Cross-checks autoplug-logs against python-can and cantools.

    python3 middleware/logs/tests/check_with_python.py     (from the workspace root or anywhere)

Needs python-can 4.x, cantools and asammdf (`pip install python-can cantools asammdf`, or
scripts/setup-tests).
It builds the `convert` example of autoplug-logs, then:

1. writes a candump log with python-can's CanutilsLogWriter (with its R/T suffix): frames
   of every message of shared/can/autoplug.dbc with random payloads, plus extended,
   remote, error, CAN FD and second-channel frames; the Rust reader must give exactly these;
2. (a) converts it with the Rust candump writer (plain, and with R/T) and reads the
   result with cantools' logreader and python-can's CanutilsLogReader;
   (b) converts it with the Rust ASC writer and reads that with python-can's ASCReader
   (cantools' logreader does not read ASC: that is checked too, for information);
   every frame's identifier, data, kind, direction and time must agree to the
   microsecond, and every catalogue frame must decode with cantools to the same
   signals as the original;
3. reads the python-can fixtures in tests/data (candump, ASC, BLF) with the Rust reader
   and with python-can's readers, and converts the BLF to ASC for python-can's ASCReader;
4. writes 6000 frames with python-can's BLFWriter and cuts the file's last 200 bytes, as a
   logger that lost power leaves it: the Rust reader must give the frames python-can reads,
   then one fatal error saying the file is truncated;
5. converts step 1's log, repeated to fill several log containers, with the Rust BLF
   writer and reads it with python-can's BLFReader: every frame the Rust reader takes from
   the candump log, to the microsecond;
6. writes the same frames with python-can's MF4Writer (asammdf
   underneath: sorted data groups, transposed DZ blocks in data lists) and saves that with
   asammdf with plain, deflate and transposed data blocks: the Rust reader must give
   every frame of each, as python-can's MF4Reader does;
7. converts step 1's log with the Rust MF4 writer (plain and
   compressed, and as the gateway records it: finished, and as a killed recorder leaves it):
   python-can's MF4Reader must read every frame of it, and asammdf every signal of every
   catalogue message, exactly as cantools decodes the frames, with the DBC's unit and the
   signal's VSS path as its display name.

Exits 1 on any disagreement, listing each.
"""

import json
import pathlib
import random
import subprocess
import sys
import tempfile

try:
    import can
    import cantools
    import cantools.logreader
    from asammdf import MDF
except ImportError as e:  # pragma: no cover
    sys.exit(f"check_with_python: {e}; install with: pip install python-can cantools asammdf"
             " (or scripts/setup-tests)")

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[2]
DBC = ROOT / "shared/can/autoplug.dbc"
T0_US = 1_700_000_000_000_000

failures = []
checks = 0


def check(what, ok, detail=""):
    global checks
    checks += 1
    if not ok:
        failures.append(f"{what}: {detail}")
        print(f"FAIL {what}: {detail}")


def convert_binary():
    subprocess.run(
        ["cargo", "build", "-q", "-p", "autoplug-logs", "--example", "convert"],
        cwd=ROOT, check=True)
    meta = json.loads(subprocess.run(
        ["cargo", "metadata", "-q", "--format-version", "1", "--no-deps"],
        cwd=ROOT, check=True, capture_output=True, text=True).stdout)
    return pathlib.Path(meta["target_directory"]) / "debug/examples/convert"


def rust_items(convert, path):
    """What the Rust reader gives: frames as dicts, errors as {"error": ...}."""
    out = subprocess.run([str(convert), "--json", str(path)], capture_output=True, text=True)
    if out.returncode != 0:
        failures.append(f"rust reader on {path.name}: {out.stderr.strip()}")
    return [json.loads(line) for line in out.stdout.splitlines()]


def rust_convert(convert, src, dst, *flags):
    out = subprocess.run([str(convert), *flags, str(src), str(dst)], capture_output=True, text=True)
    check(f"convert {src.name} -> {dst.name}", out.returncode == 0, out.stderr.strip())


def us(seconds):
    return round(seconds * 1_000_000)


def from_python(message, channel):
    """A python-can message in the form of the Rust dump."""
    if message.is_error_frame:
        kind = "error"
    elif message.is_remote_frame:
        kind = "remote"
    else:
        kind = "data"
    data = b"" if message.is_remote_frame else bytes(message.data)
    return {
        "t_us": us(message.timestamp), "channel": channel, "id": message.arbitration_id,
        "extended": message.is_extended_id, "kind": kind,
        "direction": "rx" if message.is_rx else "tx",
        "len": message.dlc if message.is_remote_frame else len(data),
        "data": data.hex().upper(),
        "fd": message.is_fd, "brs": message.is_fd and message.bitrate_switch,
        "esi": message.is_fd and message.error_state_indicator,
    }


def canutils_channel(message):
    """`can1` -> 1. python-can's candump reader keeps no channel for error frames: 0."""
    return int(message.channel[3:]) if message.channel else 0


def same(a, b, fields):
    return {k: a[k] for k in fields} == {k: b[k] for k in fields}


MF4_FIXTURES = ["python-can.mf4", "asammdf-plain.mf4", "asammdf-deflate.mf4",
                "asammdf-transposed.mf4"]

ALL = ["t_us", "channel", "id", "extended", "kind", "direction", "len", "data", "fd", "brs", "esi"]
# An error frame's identifier and flags mean different things in each format.
ERROR_FIELDS = ["t_us", "channel", "kind", "direction"]


def compare(what, rust, python, fields=ALL):
    """Rust frames against python's, in order."""
    check(f"{what}: count", len(rust) == len(python), f"rust {len(rust)}, python {len(python)}")
    for i, (r, p) in enumerate(zip(rust, python)):
        if "error" in r:
            check(f"{what}: item {i + 1}", False, f"rust error {r['error']}, python {p}")
            continue
        f = ERROR_FIELDS if p["kind"] == "error" else fields
        check(f"{what}: item {i + 1}", same(r, p, f), f"rust {r}\n      python {p}")


def decoded(db, frame_id, data):
    try:
        message = db.get_message_by_frame_id(frame_id)
    except KeyError:
        return None
    return message.decode(bytes(data), decode_choices=False)


def make_input(db):
    """The messages of step 1, and what the Rust reader must give for them."""
    rng = random.Random(2011)
    messages = []
    t = T0_US
    for message in sorted(db.messages, key=lambda m: m.frame_id):
        for _ in range(3):
            t += rng.randrange(1, 5000)
            messages.append(can.Message(
                timestamp=t / 1e6, arbitration_id=message.frame_id, is_extended_id=False,
                data=bytes(rng.randrange(256) for _ in range(message.length)),
                is_rx=rng.random() < 0.8, channel=0))
    extras = [
        can.Message(arbitration_id=0x1ABCDEF0, is_extended_id=True, data=b"\x01\x02\x03", channel=0),
        can.Message(arbitration_id=0x00000123, is_extended_id=True, data=b"", is_rx=False, channel=0),
        can.Message(arbitration_id=0x123, is_extended_id=False, is_remote_frame=True, channel=0),
        can.Message(is_error_frame=True, channel=0),
        can.Message(arbitration_id=0x003, is_extended_id=False, data=b"\x64", channel=1),
        can.Message(arbitration_id=0x456, is_extended_id=False, is_fd=True, bitrate_switch=True,
                    data=bytes(range(12)), channel=0),
        can.Message(arbitration_id=0x1ABCDEF0, is_extended_id=True, is_fd=True,
                    error_state_indicator=True, data=bytes(range(64)), is_rx=False, channel=1),
        can.Message(arbitration_id=0x7FF, is_extended_id=False, is_fd=True, data=b"", channel=0),
    ]
    for extra in extras:
        t += 1_000_001
        extra.timestamp = t / 1e6
        messages.append(extra)
    expected = [from_python(m, m.channel) for m in messages]
    # python-can writes error frames as CAN_ERR_FLAG | CAN_ERR_BUSERROR: class 0x80.
    for e, m in zip(expected, messages):
        if m.is_error_frame:
            e["id"], e["extended"] = 0x80, False
    return messages, expected


def truncated_blf(convert, tmp):
    """Step 4: a BLF cut short, read by python-can and by the Rust reader."""
    rng = random.Random(6000)
    path = tmp / "cut.blf"
    writer = can.BLFWriter(path)
    t = T0_US
    for _ in range(6000):
        writer.on_message_received(can.Message(
            timestamp=t / 1e6, arbitration_id=rng.randrange(0x800), is_extended_id=False,
            data=bytes(rng.randrange(256) for _ in range(rng.randrange(9))),
            is_rx=rng.random() < 0.8, channel=0))
        t += rng.randrange(100, 2000)
    writer.stop()
    path.write_bytes(path.read_bytes()[:-200])
    python = [from_python(m, m.channel) for m in can.BLFReader(path)]
    out = subprocess.run([str(convert), "--json", str(path)], capture_output=True, text=True)
    items = [json.loads(line) for line in out.stdout.splitlines()]
    last = items[-1] if items else {}
    check("rust on a BLF cut short: one fatal error at the end",
          last.get("fatal") is True and "truncated file?" in last.get("error", "")
          and sum("error" in i for i in items) == 1, str(last))
    check("python-can reads most of the BLF cut short", 5900 < len(python) < 6000, str(len(python)))
    compare("rust and python-can read a BLF cut short", items[:-1], python)


def mf4_written(convert, tmp, db, source, expected):
    """Step 7: AutoPlug's MF4, read by python-can (frames) and asammdf (signals)."""
    for flags, name in [([], "rust.mf4"), (["--compress"], "rust-compressed.mf4"),
                        (["--recording"], "rust-recording.mf4"),
                        (["--recording", "--crash"], "rust-recording-killed.mf4")]:
        path = tmp / name
        rust_convert(convert, source, path, *flags)
        python = [from_python(m, m.channel) for m in can.MF4Reader(path)]
        # MF4 keeps frames by type (data, error, remote), each group in time order.
        want = sorted(expected, key=lambda e: e["t_us"])
        compare(f"python-can MF4Reader reads rust's {name}", sorted(python, key=lambda e: e["t_us"]), want)
        mdf = MDF(path)
        start_us = round(mdf.header.start_time.timestamp() * 1e6)
        groups = {g.channel_group.acq_name: i for i, g in enumerate(mdf.groups)}
        signals = 0
        # The periodic messages; the diagnostic transport ones (0x700 and up) carry ISO-TP
        # payloads, not signals, and have no group of decoded signals.
        periodic = [m for m in db.messages if m.frame_id < 0x700]
        for message in periodic:
            frames = [e for e in expected if e["kind"] == "data" and not e["extended"]
                      and not e["fd"] and e["id"] == message.frame_id
                      and e["len"] == message.length]
            index = groups.get(message.name)
            check(f"{name}: a channel group for {message.name}", index is not None, str(groups))
            if index is None:
                continue
            for signal in message.signals:
                got = mdf.get(signal.name, group=index, raw=False)
                want_values = [message.decode(bytes.fromhex(f["data"]), decode_choices=False,
                                              scaling=True)[signal.name] for f in frames]
                times = [round(t * 1e6) + start_us for t in got.timestamps]
                check(f"{name}: {message.name}.{signal.name} times",
                      times == [f["t_us"] for f in frames], f"{times[:3]} ...")
                check(f"{name}: {message.name}.{signal.name} values",
                      len(got.samples) == len(want_values)
                      and all(abs(float(a) - float(b)) <= 1e-9 * max(1.0, abs(float(b)))
                              for a, b in zip(got.samples, want_values)),
                      f"{list(got.samples[:3])} != {want_values[:3]}")
                check(f"{name}: {message.name}.{signal.name} unit", got.unit == (signal.unit or ""),
                      f"{got.unit!r} != {signal.unit!r}")
                vss = (signal.dbc.attributes.get("VssPath").value
                       if signal.dbc and "VssPath" in signal.dbc.attributes else "")
                if vss:
                    check(f"{name}: {message.name}.{signal.name} VSS display name",
                          vss in got.display_names, str(got.display_names))
                signals += 1
        check(f"{name}: every signal of the periodic messages read",
              signals == sum(len(m.signals) for m in periodic) and len(periodic) == 18, str(signals))


def main():
    db = cantools.database.load_file(str(DBC))
    convert = convert_binary()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        messages, expected = make_input(db)
        source = tmp / "input.log"
        writer = can.CanutilsLogWriter(source)
        for m in messages:
            writer.on_message_received(m)
        writer.stop()

        # 1. The Rust reader on python-can's candump.
        rust = rust_items(convert, source)
        compare("rust reads python-can's candump", rust, expected)

        # 2a. The Rust candump writer, read by cantools and python-can.
        plain, with_rt, asc = tmp / "out.log", tmp / "out-rt.log", tmp / "out.asc"
        rust_convert(convert, source, plain)
        rust_convert(convert, source, with_rt, "--direction")
        rust_convert(convert, source, asc)
        for path, directions in [(plain, False), (with_rt, True)]:
            want = [dict(e) for e in expected]
            if not directions:
                for e in want:
                    e["direction"] = "rx"
            with open(path) as fd:
                got = list(cantools.logreader.Parser(fd))
            no_errors = [e for e in want if e["kind"] != "error"]
            cantools_frames = [{
                "t_us": us(f.timestamp.timestamp()), "channel": int(f.channel[3:]),
                "id": f.frame_id, "extended": f.is_extended_frame,
                "kind": "remote" if f.is_remote_frame else "data",
                "direction": "rx", "len": len(f.data), "data": f.data.hex().upper(),
            } for f in got]
            compare(f"cantools logreader reads rust's {path.name}", cantools_frames, no_errors,
                    ["t_us", "channel", "id", "extended", "kind", "data"])
            for f, m in zip(got, [m for m in messages if not m.is_error_frame]):
                if not f.is_remote_frame:
                    original = decoded(db, m.arbitration_id, m.data) if not m.is_extended_id else None
                    again = decoded(db, f.frame_id, f.data) if not f.is_extended_frame else None
                    check(f"cantools decodes {path.name} frame {f.frame_id:#x}", original == again,
                          f"{original} != {again}")
            python = [from_python(m, canutils_channel(m)) for m in can.CanutilsLogReader(path)]
            compare(f"python-can CanutilsLogReader reads rust's {path.name}", python, want)

        # 2b. The Rust ASC writer, read by python-can (and not by cantools).
        with open(asc) as fd:
            n = len(list(cantools.logreader.Parser(fd)))
        print(f"info: cantools.logreader finds {n} frames in an ASC file"
              + (" (it does not read ASC: python-can's ASCReader is used)" if n == 0 else ""))
        got = list(can.ASCReader(asc))
        python = [from_python(m, m.channel) for m in got]
        for p in python:
            # python-can 4.6's ASCReader takes a CANFD event of data length 0 for a remote
            # frame; CAN FD has none (the FDF flag, 0x1000, is set on the line).
            if p["fd"] and p["kind"] == "remote" and p["len"] == 0:
                p["kind"] = "data"
        want = [dict(e, t_us=e["t_us"] - expected[0]["t_us"]) for e in expected]
        for e in want:
            if e["kind"] == "remote":
                e["len"] = 0  # python-can's candump writer dropped the DLC
        compare("python-can ASCReader reads rust's out.asc", python, want)
        decodes = 0
        for m, original in zip(got, messages):
            if m.is_error_frame or m.is_remote_frame or m.is_extended_id:
                continue
            a, b = decoded(db, original.arbitration_id, original.data), decoded(db, m.arbitration_id, m.data)
            check(f"cantools decodes out.asc frame {m.arbitration_id:#x}", a == b, f"{a} != {b}")
            decodes += a is not None
        check("catalogue frames decoded from ASC", decodes >= len(db.messages) * 3, str(decodes))

        # 3. The python-can fixtures, Rust against python-can.
        data = HERE / "data"
        fixtures = [
            ("python-can.log", lambda p: can.CanutilsLogReader(p), canutils_channel),
            ("python-can.asc", lambda p: can.ASCReader(p), lambda m: m.channel),
            ("python-can.blf", lambda p: can.BLFReader(p), lambda m: m.channel),
            ("python-can-stored.blf", lambda p: can.BLFReader(p), lambda m: m.channel),
            ("python-can-split.blf", lambda p: can.BLFReader(p), lambda m: m.channel),
        ]
        fixtures += [(name, lambda p: can.MF4Reader(p), lambda m: m.channel)
                     for name in MF4_FIXTURES]
        for name, reader, channel in fixtures:
            python = [from_python(m, channel(m)) for m in reader(data / name)]
            compare(f"rust and python-can read {name}", rust_items(convert, data / name), python)
        blf_asc = tmp / "blf.asc"
        rust_convert(convert, data / "python-can.blf", blf_asc)
        blf = list(can.BLFReader(data / "python-can.blf"))
        t0 = us(blf[0].timestamp)
        want = [dict(from_python(m, m.channel), t_us=us(m.timestamp) - t0) for m in blf]
        python = [from_python(m, m.channel) for m in can.ASCReader(blf_asc)]
        compare("python-can ASCReader reads rust's ASC of python-can.blf", python, want)

        # 4. A BLF cut short.
        truncated_blf(convert, tmp)

        # 5. The Rust BLF writer, read by python-can: step 1's frames, and enough more
        # (the same, 40 times, a second apart) to fill several log containers.
        big = tmp / "big.log"
        writer = can.CanutilsLogWriter(big)
        span = messages[-1].timestamp - messages[0].timestamp + 1
        many = []
        for k in range(40):
            for m in messages:
                copy = can.Message(timestamp=m.timestamp + k * span, arbitration_id=m.arbitration_id,
                                   is_extended_id=m.is_extended_id, is_remote_frame=m.is_remote_frame,
                                   is_error_frame=m.is_error_frame, dlc=m.dlc, data=m.data,
                                   is_rx=m.is_rx, channel=m.channel, is_fd=m.is_fd,
                                   bitrate_switch=m.bitrate_switch,
                                   error_state_indicator=m.error_state_indicator)
                writer.on_message_received(copy)
                many.append(copy)
        writer.stop()
        blf_out = tmp / "out.blf"
        rust_convert(convert, big, blf_out)
        # What the Rust reader takes from the candump log (step 1 holds it to python-can).
        want = rust_items(convert, big)
        check("the repeated log is read whole", len(want) == len(many), f"{len(want)} of {len(many)}")
        python = [from_python(m, m.channel) for m in can.BLFReader(blf_out)]
        compare("python-can BLFReader reads rust's out.blf", python, want)
        raw, at, containers = blf_out.read_bytes(), 144, 0
        while at + 16 <= len(raw) and raw[at:at + 4] == b"LOBJ":
            size = int.from_bytes(raw[at + 8:at + 12], "little")
            containers += int.from_bytes(raw[at + 12:at + 16], "little") == 10
            at += size + size % 4
        check("rust's out.blf is log containers to its end, several of them",
              at == len(raw) and containers >= 2, f"{containers} containers, {at} of {len(raw)} bytes")

        # 6. MF4 as python-can and asammdf write it, read by Rust and by python-can.
        mf4 = tmp / "many.mf4"
        writer = can.MF4Writer(mf4)
        for m in many:
            writer.on_message_received(m)
        writer.stop()
        variants = [mf4]
        for compression, name in [(0, "plain"), (1, "deflate"), (2, "transposed")]:
            path = tmp / f"many-{name}.mf4"
            MDF(mf4).save(path, overwrite=True, compression=compression)
            variants.append(path)
        for path in variants:
            rust = rust_items(convert, path)
            # python-can's MF4Writer keeps each time as (message time - the time the
            # writer was opened) in f64 seconds, both times floats of Unix seconds
            # (0.24 µs apart there): a time read back may be 1 µs off the original.
            off = 0
            original = [dict(w) for w in want]
            for r, w in zip(rust, original):
                if "t_us" in r and r["t_us"] != w["t_us"] and abs(r["t_us"] - w["t_us"]) <= 1:
                    off += 1
                    w["t_us"] = r["t_us"]
            print(f"info: {path.name}: {off} of {len(original)} times 1 µs off the original"
                  " (python-can's float times)")
            compare(f"rust reads {path.name} as the log it was written from", rust, original)
            python = [from_python(m, m.channel) for m in can.MF4Reader(path)]
            check(f"python-can reads every frame of {path.name}", len(python) == len(many),
                  f"{len(python)} of {len(many)}")
            # python-can adds the file's start (seconds since 1970) to each record's
            # time as floats, which carry 0.24 µs there: its times may be 1 µs off.
            near = 0
            for r, p in zip(rust, python):
                near += abs(r.get("t_us", 0) - p["t_us"]) <= 1
                p["t_us"] = r.get("t_us", p["t_us"])
            check(f"python-can's times of {path.name} within 1 µs of rust's",
                  near == len(python), f"{near} of {len(python)}")
            compare(f"rust and python-can read {path.name}", rust, python)

        # 7. The Rust MF4 writer, read by python-can and asammdf.
        mf4_written(convert, tmp, db, source, expected)

    if failures:
        print(f"\n{len(failures)} of {checks} checks FAILED")
        return 1
    print(f"all {checks} checks passed (python-can {can.__version__}, cantools {cantools.__version__})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
