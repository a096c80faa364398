#!/usr/bin/env python3
"""A gateway recording and its ASC export, read by cantools and python-can.

    python3 scripts/recording-check.py DBC RECORDING.log EXPORT.asc REFERENCE.log [EXPORT.mcap]
        [--mf4 FILE.mf4]...

RECORDING.log is what `autoplug gateway --record` wrote, EXPORT.asc what
`autoplug log export` made of it, REFERENCE.log the virtual car's own bus log of the same
run. The recording is read with cantools' logreader, the export with python-can's
ASCReader (cantools' logreader has no ASC parser); every catalogue frame of both is
decoded with cantools against the DBC (strict: a value outside its range fails), and both
must hold exactly the reference's frames, in order, with the same identifiers and data
(the ASC export's times are relative to its first frame, so times are compared as
offsets from the first frame, to the microsecond). EXPORT.mcap, if given, is read with
the mcap package: its raw channel must hold every frame, and each message channel's
decoded signals must equal cantools' decoding of the same frame (to float precision). Each
--mf4 file (the recording exported to MF4, the gateway's own MF4 recording) is read with
python-can's MF4Reader, which must give exactly the ASC export's frames (times as offsets
from the first, to the microsecond), and with asammdf, whose every signal of every
catalogue message must equal cantools' decoding of the ASC export's frames, at their times.
Exits 1 on any disagreement.
"""

import sys

try:
    import can
    import cantools
    import cantools.logreader
except ImportError as e:  # pragma: no cover
    sys.exit(f"recording-check: {e}; run scripts/setup-tests (it installs them into .venv)")


def seconds(timestamp):
    # cantools gives a datetime for candump's absolute times.
    return timestamp.timestamp() if hasattr(timestamp, "timestamp") else timestamp


def candump_frames(path):
    with open(path) as f:
        return [(round(seconds(m.timestamp) * 1e6), m.frame_id, bytes(m.data))
                for m in cantools.logreader.Parser(f)]


def asc_frames(path):
    return [(round(m.timestamp * 1e6), m.arbitration_id, bytes(m.data))
            for m in can.ASCReader(path) if not m.is_error_frame]


def relative(frames):
    t0 = frames[0][0] if frames else 0
    return [(t - t0, i, d) for t, i, d in frames]


def check_mcap(db, catalogue, rec, path, failures):
    import json
    try:
        from mcap.reader import make_reader
    except ImportError as e:  # pragma: no cover
        sys.exit(f"recording-check: {e}; run scripts/setup-tests (it installs it into .venv)")
    raw, decoded = [], []
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            body = json.loads(message.data)
            if channel.topic == "/can/frames":
                raw.append((message.log_time // 1000, body["id"], bytes(body["data"])))
            else:
                decoded.append((message.log_time // 1000, channel.topic[1:], body))
    if raw != rec:
        failures.append(f"MCAP raw channel: {len(raw)} frames, recording {len(rec)}")
    expected = []
    for t, frame_id, data in rec:
        if frame_id in catalogue:
            msg = db.get_message_by_frame_id(frame_id)
            expected.append((t, msg.name, db.decode_message(frame_id, data, decode_choices=False)))
    if len(expected) != len(decoded):
        failures.append(f"MCAP: {len(decoded)} decoded messages, cantools decodes {len(expected)}")
        return 0
    for (t1, name1, ours), (t2, name2, theirs) in zip(decoded, expected):
        same = (t1, name1) == (t2, name2) and ours.keys() == theirs.keys() and all(
            abs(ours[k] - theirs[k]) <= 1e-4 * max(1.0, abs(theirs[k])) for k in ours)
        if not same:
            failures.append(f"MCAP {name1} at {t1} us: {ours}, cantools {name2} at {t2} us: {theirs}")
            return 0
    return len(decoded)


def check_mf4(db, catalogue, asc, path, failures):
    """An MF4 of the drive against the ASC export: python-can's frames, asammdf's signals."""
    try:
        from asammdf import MDF
    except ImportError as e:  # pragma: no cover
        sys.exit(f"recording-check: {e}; run scripts/setup-tests (it installs it into .venv)")
    frames = [(round(m.timestamp * 1e6), m.arbitration_id, bytes(m.data))
              for m in can.MF4Reader(path) if not m.is_error_frame]
    if relative(frames) != relative(asc):
        failures.append(f"{path}: python-can reads {len(frames)} frames, the ASC export has "
                        f"{len(asc)}, or different ones")
    mdf = MDF(path)
    start_us = round(mdf.header.start_time.timestamp() * 1e6)
    t0 = frames[0][0] if frames else 0
    groups = {g.channel_group.acq_name: i for i, g in enumerate(mdf.groups)}
    asc_t0 = asc[0][0] if asc else 0
    values = 0
    for frame_id in sorted(catalogue):
        message = db.get_message_by_frame_id(frame_id)
        mine = [(t - asc_t0, d) for t, i, d in asc if i == frame_id and len(d) == message.length]
        index = groups.get(message.name)
        if index is None:
            failures.append(f"{path}: no channel group {message.name}")
            continue
        for signal in message.signals:
            got = mdf.get(signal.name, group=index)
            want = [message.decode(d, decode_choices=False)[signal.name] for _, d in mine]
            times = [round(t * 1e6) + start_us - t0 for t in got.timestamps]
            if times != [t for t, _ in mine] or len(got.samples) != len(want) or any(
                    abs(float(a) - float(b)) > 1e-9 * max(1.0, abs(float(b)))
                    for a, b in zip(got.samples, want)):
                failures.append(f"{path}: {message.name}.{signal.name}: asammdf's values or times "
                                "differ from cantools' decoding of the ASC export")
                continue
            values += len(want)
    return len(frames), values


def main():
    args = sys.argv[1:]
    mf4_paths = []
    while "--mf4" in args:
        at = args.index("--mf4")
        if at + 1 >= len(args):
            sys.exit(__doc__)
        mf4_paths.append(args[at + 1])
        del args[at:at + 2]
    if len(args) not in (4, 5):
        sys.exit(__doc__)
    dbc, recording, export, reference = args[:4]
    mcap_path = args[4] if len(args) == 5 else None
    db = cantools.database.load_file(dbc)
    catalogue = {m.frame_id for m in db.messages if not m.name.startswith(("Diag", "Obd"))}
    ref = candump_frames(reference)
    rec = candump_frames(recording)
    asc = asc_frames(export)
    failures = []
    if rec != ref:
        failures.append(f"recording: {len(rec)} frames, reference {len(ref)}; first difference "
                        f"{next((a, b) for a, b in zip(rec, ref) if a != b) if len(rec) == len(ref) else 'in length'}")
    if relative(asc) != relative(ref):
        failures.append(f"ASC export: {len(asc)} frames, reference {len(ref)}, or different frames")
    decoded = 0
    for source, frames in (("recording", rec), ("ASC export", asc)):
        for t, frame_id, data in frames:
            if frame_id not in catalogue:
                continue
            try:
                db.decode_message(frame_id, data, decode_choices=False)
                decoded += 1
            except Exception as e:  # cantools raises several kinds
                failures.append(f"{source}: frame {frame_id:03X}#{data.hex()} at {t} us: {e}")
                break
    mcap_decoded = 0
    if mcap_path:
        mcap_decoded = check_mcap(db, catalogue, rec, mcap_path, failures)
    mf4_summaries = [f"{p}: {n} frames, {v} signal values"
                     for p, (n, v) in ((p, check_mf4(db, catalogue, asc, p, failures))
                                       for p in mf4_paths)]
    for f in failures:
        print(f"FAIL {f}")
    for line in mf4_summaries:
        print(f"MF4 {line} as the ASC export and cantools have them")
    print(f"recording-check: {len(rec)} frames recorded, {len(asc)} exported to ASC, "
          f"{decoded} catalogue frames decoded by cantools, {mcap_decoded} MCAP messages "
          f"matching cantools' decoding, {len(failures)} failure(s)")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
