#!/usr/bin/env python3
"""Read a run directory's TensorBoard event file with the Python standard library
only (struct and a table CRC32C; no tensorboard wheel is in the pinned venv) and
check it against the run's metrics.csv:

* the directory holds exactly one `events.out.tfevents.*` file;
* every record's framing: u64 length LE, masked CRC32C of the length, the data,
  masked CRC32C of the data (both CRCs checked), nothing cut at the end;
* every record is a protobuf `Event`: the first has file_version "brain.Event:2",
  then one per metrics.csv row at step = the row's first column (`iteration`),
  whose summary values are the row's non-NaN cells in column order (as float32,
  bit for bit), each tagged `<Group>/<column>` with Group one of Train, Loss,
  Policy, Perf, Episode, or with rsl_rl's name for the columns that take one.

    python3 scripts/check_tfevents_python.py RUN_DIR...

Exit 1 naming the file and the record on the first problem.
"""
import math
import pathlib
import struct
import sys

GROUPS = {"Train", "Loss", "Policy", "Perf", "Episode"}
# src/run/tensorboard.rs, RSL_RL_TAGS
RSL_RL_TAGS = {
    "mean_return": "Train/mean_reward",
    "mean_episode_length": "Train/mean_episode_length",
    "value_loss": "Loss/value_function",
    "surrogate_loss": "Loss/surrogate",
    "entropy": "Loss/entropy",
    "learning_rate": "Loss/learning_rate",
    "mean_std": "Policy/mean_noise_std",
    "env_steps_per_s": "Perf/total_fps",
    "time_update_s": "Perf/learning_time",
}


def _crc_table():
    table = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ 0x82F63B78 if c & 1 else c >> 1
        table.append(c)
    return table


CRC_TABLE = _crc_table()


def crc32c(data):
    c = 0xFFFFFFFF
    for b in data:
        c = CRC_TABLE[(c ^ b) & 0xFF] ^ (c >> 8)
    return c ^ 0xFFFFFFFF


def masked_crc32c(data):
    c = crc32c(data)
    return (((c >> 15) | (c << 17)) + 0xA282EAD8) & 0xFFFFFFFF


class Bad(Exception):
    pass


def records(data):
    """(offset, payload) of every TFRecord, both CRCs checked."""
    at = 0
    while at < len(data):
        if len(data) - at < 12:
            raise Bad(f"record at byte {at}: cut inside its header")
        (length,) = struct.unpack_from("<Q", data, at)
        (len_crc,) = struct.unpack_from("<I", data, at + 8)
        if masked_crc32c(data[at : at + 8]) != len_crc:
            raise Bad(f"record at byte {at}: length CRC mismatch")
        end = at + 12 + length + 4
        if end > len(data):
            raise Bad(f"record at byte {at}: cut inside its data")
        payload = data[at + 12 : at + 12 + length]
        (data_crc,) = struct.unpack_from("<I", data, end - 4)
        if masked_crc32c(payload) != data_crc:
            raise Bad(f"record at byte {at}: data CRC mismatch")
        yield at, payload
        at = end


def varint(buf, i):
    v, shift = 0, 0
    while True:
        if i >= len(buf) or shift > 63:
            raise Bad("bad varint")
        b = buf[i]
        i += 1
        v |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return v, i


def fields(buf):
    """(field number, wire type, value) of a protobuf message."""
    i = 0
    while i < len(buf):
        key, i = varint(buf, i)
        field, wire = key >> 3, key & 7
        if wire == 0:
            value, i = varint(buf, i)
        elif wire == 1:
            value, i = buf[i : i + 8], i + 8
        elif wire == 2:
            n, i = varint(buf, i)
            value, i = buf[i : i + n], i + n
        elif wire == 5:
            value, i = buf[i : i + 4], i + 4
        else:
            raise Bad(f"wire type {wire} of field {field}")
        if i > len(buf):
            raise Bad(f"field {field} cut short")
        yield field, wire, value


def event(buf):
    """Event -> dict(wall_time, step, file_version, scalars=[(tag, float32)])."""
    e = {"wall_time": 0.0, "step": 0, "file_version": None, "scalars": []}
    for field, wire, value in fields(buf):
        if (field, wire) == (1, 1):
            (e["wall_time"],) = struct.unpack("<d", value)
        elif (field, wire) == (2, 0):
            e["step"] = value - (1 << 64) if value >= 1 << 63 else value
        elif (field, wire) == (3, 2):
            e["file_version"] = bytes(value).decode()
        elif (field, wire) == (5, 2):
            for f, w, v in fields(value):
                if (f, w) != (1, 2):
                    continue
                tag, simple = None, None
                for vf, vw, vv in fields(v):
                    if (vf, vw) == (1, 2):
                        tag = bytes(vv).decode()
                    elif (vf, vw) == (2, 5):
                        (simple,) = struct.unpack("<f", vv)
                if tag is not None and simple is not None:
                    e["scalars"].append((tag, simple))
        elif field in (1, 2, 3, 5):
            raise Bad(f"Event field {field} has wire type {wire}")
    return e


def float32(x):
    try:
        return struct.unpack("<f", struct.pack("<f", x))[0]
    except OverflowError:
        return math.copysign(math.inf, x)


def same(a, b):
    return struct.pack("<f", a) == struct.pack("<f", b)


def check_run(run_dir):
    files = sorted(run_dir.glob("events.out.tfevents.*"))
    if len(files) != 1:
        raise Bad(f"{run_dir}: {len(files)} event files, expected one")
    path = files[0]
    data = path.read_bytes()
    try:
        events = [(at, event(p)) for at, p in records(data)]
    except Bad as e:
        raise Bad(f"{path}: {e}") from None
    lines = (run_dir / "metrics.csv").read_text().splitlines()
    columns = lines[0].split(",")
    rows = [[float(v) for v in l.split(",")] for l in lines[1:]]
    if not events or events[0][1]["file_version"] != "brain.Event:2":
        raise Bad(f"{path}: the first event is not file_version brain.Event:2")
    if len(events) != len(rows) + 1:
        raise Bad(f"{path}: {len(events) - 1} scalar events for {len(rows)} metrics rows")
    n_scalars = 0
    for (at, e), row in zip(events[1:], rows):
        where = f"{path}: record at byte {at} (step {e['step']})"
        if e["step"] != row[0]:
            raise Bad(f"{where}: step is not the row's {columns[0]} {row[0]}")
        want = [(c, v) for c, v in zip(columns[1:], row[1:]) if not math.isnan(v)]
        if len(e["scalars"]) != len(want):
            raise Bad(f"{where}: {len(e['scalars'])} values for {len(want)} non-NaN cells")
        for (tag, value), (column, cell) in zip(e["scalars"], want):
            group, _, name = tag.partition("/")
            if group not in GROUPS or (name != column and RSL_RL_TAGS.get(column) != tag):
                raise Bad(f"{where}: tag {tag!r} for column {column!r}")
            if not same(value, float32(cell)):
                raise Bad(f"{where}: {tag} = {value}, metrics.csv {column} = {cell}")
        n_scalars += len(e["scalars"])
    steps = [e["step"] for _, e in events[1:]]
    if steps != sorted(set(steps)):
        raise Bad(f"{path}: steps repeat or go back: {steps}")
    print(
        f"{path}: {len(events)} events (CRCs ok), steps {steps[0]}..{steps[-1]}, "
        f"{n_scalars} scalars = metrics.csv"
        if steps
        else f"{path}: {len(events)} events (CRCs ok), no rows"
    )


def main(argv):
    if not argv or argv[0].startswith("-"):
        print(__doc__)
        return 2
    try:
        for d in argv:
            check_run(pathlib.Path(d))
    except (Bad, OSError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
