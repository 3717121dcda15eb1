"""Damaged bags: a clear error naming the bag and file, and the readable part salvaged.

The MCAP cases are checked exactly: the messages salvaged from a truncated file are those of the
chunks that end before the cut, byte for byte; a damaged chunk loses its own messages only.
"""

from __future__ import annotations

import io
import os
import shutil
import sqlite3
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap import records
from mcap.stream_reader import StreamReader, breakup_chunk
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from transparency_ros.bag.errors import BagReadError
from transparency_ros.bag.keys import SALVAGED_KEY
from transparency_ros.bag.reader import joint_series, open_bag
from transparency_ros.bag.salvage import salvage
from transparency_ros.bag.writer import BagWriter
from transparency_ros.cli import main
from transparency_ros.core.cdr import encode_joint_state, encode_wrench_stamped

CUSTOM = {"transparency.trial": "drop_test", "transparency.actuator": "U10DD"}
Message = tuple[str, int, bytes]


def _joint(i: int) -> bytes:
    return encode_joint_state(
        i // 1000, (i % 1000) * 10**6, "", ["a", "b", "c", "d", "e", "f"],
        position=[i * 1e-3 + k for k in range(6)], velocity=[0.0] * 6, effort=[float(i)] * 6,
    )  # fmt: skip


def _write_bag(path: Path, n: int) -> list[Message]:
    """A bag of several MCAP chunks (rosbags closes one at 1 MB): /joint_states and
    /load_cell interleaved."""
    written: list[Message] = []
    with BagWriter(path, CUSTOM) as bag:
        bag.add("/joint_states", "sensor_msgs/msg/JointState")
        bag.add("/load_cell", "geometry_msgs/msg/WrenchStamped")
        for i in range(n):
            t = 10**18 + i * 10**6
            for topic, data in (
                ("/joint_states", _joint(i)),
                (
                    "/load_cell",
                    encode_wrench_stamped(
                        i // 1000, i % 1000, "lc", (0.0, 0.0, i), (0.0, 0.0, 0.0)
                    ),
                ),
            ):
                bag.write(topic, t, data)
                written.append((topic, t, data))
    return written


@pytest.fixture(scope="module")
def chunked(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Message]]:
    path = tmp_path_factory.mktemp("salvage") / "bag"
    return path, _write_bag(path, 12_000)


def _chunks(mcap: Path) -> list[tuple[int, int, list[Message]]]:
    """(start, end byte, messages) of each chunk of an intact file, in file order."""
    data = mcap.read_bytes()
    stream, start, channels = io.BytesIO(data), 0, {}
    out = []
    for record in StreamReader(stream, emit_chunks=True).records:
        if isinstance(record, records.Chunk):
            msgs = []
            for inner in breakup_chunk(record):
                if isinstance(inner, records.Channel):
                    channels[inner.id] = inner.topic
                elif isinstance(inner, records.Message):
                    msgs.append((channels[inner.channel_id], inner.log_time, bytes(inner.data)))
            out.append((start, stream.tell(), msgs))
        start = stream.tell()
    return out


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return next(dst.glob("*.mcap"))


def _salvaged(path: Path) -> list[Message]:
    with open_bag(path) as bag:
        return [(c.topic, t, bytes(d)) for c, t, d in bag.raw(sorted(bag.topics))]


def _in_file_order(messages: list[Message], order: list[Message]) -> list[Message]:
    rank = {m: i for i, m in enumerate(order)}
    return sorted(messages, key=rank.__getitem__)


@pytest.mark.parametrize("cut", [0.35, 0.7, 0.95, 0.9999])
def test_a_truncated_mcap_keeps_every_whole_chunk(
    chunked: tuple[Path, list[Message]], tmp_path: Path, cut: float
) -> None:
    source, written = chunked
    mcap = next(source.glob("*.mcap"))
    chunks = _chunks(mcap)
    assert len(chunks) >= 3
    damaged = _copy(source, tmp_path / "cut")
    size = round(mcap.stat().st_size * cut)
    damaged.write_bytes(mcap.read_bytes()[:size])
    with pytest.raises(BagReadError, match=rf"cut: cannot open: file {damaged.name}.*salvage"):
        open_bag(tmp_path / "cut").__enter__()

    report = salvage(tmp_path / "cut", tmp_path / "out")
    expected = [m for start, end, msgs in chunks if end <= size for m in msgs]
    assert expected, "the cut should leave at least one whole chunk"
    got = _in_file_order(_salvaged(tmp_path / "out"), written)
    assert got == expected  # byte for byte, none lost before the cut, none invented
    assert report.total == len(expected)
    assert report.recorded == {"/joint_states": 12_000, "/load_cell": 12_000}
    assert any(f"{damaged.name}: ends after byte" in d for d in report.damage)
    with open_bag(tmp_path / "out") as bag:
        assert {k: bag.custom_data[k] for k in CUSTOM} == CUSTOM
        assert "ends after byte" in bag.custom_data[SALVAGED_KEY]
        series = joint_series(bag, "/joint_states")  # the fast path reads the salvaged bag
    assert series.stamp_s.size == sum(t == "/joint_states" for t, _, _ in expected)


def test_a_damaged_chunk_loses_only_its_own_messages(
    chunked: tuple[Path, list[Message]], tmp_path: Path
) -> None:
    source, written = chunked
    mcap = next(source.glob("*.mcap"))
    chunks = _chunks(mcap)
    start, end, lost = chunks[1]
    data = bytearray(mcap.read_bytes())
    middle = (start + end) // 2
    data[middle : middle + 64] = b"\xff" * 64  # inside the compressed records
    damaged = _copy(source, tmp_path / "bad")
    damaged.write_bytes(bytes(data))
    with open_bag(tmp_path / "bad") as bag:  # the summary is intact: it opens
        with pytest.raises(BagReadError, match=r"bad: reading /joint_states: .*salvage"):
            joint_series(bag, "/joint_states")
        with pytest.raises(BagReadError, match=r"reading /load_cell"):
            list(bag.messages(["/load_cell"]))

    report = salvage(tmp_path / "bad", tmp_path / "out")
    assert _in_file_order(_salvaged(tmp_path / "out"), written) == [
        m for m in written if m not in set(lost)
    ]
    assert any("a chunk of" in d and "skipped" in d for d in report.damage), report.damage


def test_the_first_chunk_damaged_later_chunks_still_salvaged(
    chunked: tuple[Path, list[Message]], tmp_path: Path
) -> None:
    """rosbag2 and rosbags put the schemas and channels in the first chunk; the summary's copy
    keeps the other chunks readable."""
    source, written = chunked
    mcap = next(source.glob("*.mcap"))
    start, end, lost = _chunks(mcap)[0]
    data = bytearray(mcap.read_bytes())
    data[(start + end) // 2 : (start + end) // 2 + 64] = b"\x00" * 64
    _copy(source, tmp_path / "bad").write_bytes(bytes(data))
    salvage(tmp_path / "bad", tmp_path / "out")
    assert _in_file_order(_salvaged(tmp_path / "out"), written) == [
        m for m in written if m not in set(lost)
    ]


def _sqlite_bag(path: Path, n: int) -> list[Message]:
    store = get_typestore(Stores.ROS2_JAZZY)
    written = []
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        for i in range(n):
            data = _joint(i)
            writer.write(conn, 10**18 + i, data)
            written.append(("/joint_states", 10**18 + i, data))
    return written


def _read_all(path: Path) -> None:
    with open_bag(path) as bag:
        list(bag.raw(sorted(bag.topics)))


@pytest.mark.parametrize("damage", ["truncated", "page overwritten"])
def test_a_damaged_sqlite3_bag_is_salvaged_row_by_row(tmp_path: Path, damage: str) -> None:
    written = _sqlite_bag(tmp_path / "bag", 5000)
    (db,) = (tmp_path / "bag").glob("*.db3")
    data = bytearray(db.read_bytes())
    page = sqlite3.connect(db).execute("PRAGMA page_size").fetchone()[0]
    pages = len(data) // page
    if damage == "truncated":
        data = data[: (pages * 3 // 4) * page + 100]
    else:
        at = (pages // 2) * page
        data[at : at + page] = os.urandom(page)
    db.write_bytes(bytes(data))
    with pytest.raises(BagReadError, match=rf"{db.parent}: .*salvage"):
        _read_all(tmp_path / "bag")

    report = salvage(tmp_path / "bag", tmp_path / "out")
    got = _salvaged(tmp_path / "out")
    assert set(got) <= set(written)  # nothing altered or invented
    assert 0.5 * len(written) < len(got) < len(written)  # most of it, and the loss is real
    assert report.kept == {"/joint_states": len(got)}
    assert any("unreadable" in d for d in report.damage), report.damage


@pytest.mark.parametrize(
    "text",
    [
        "rosbag2_bagfile_information: [\n",  # not YAML
        "rosbag2_bagfile_information: a string\n",  # found by `make fuzz`
        "rosbag2_bagfile_information:\n  custom_data: [1]\n",
    ],
)
def test_a_broken_metadata_yaml_takes_custom_data_from_the_storage(
    chunked: tuple[Path, list[Message]], tmp_path: Path, text: str
) -> None:
    source, written = chunked
    _copy(source, tmp_path / "bag")
    (tmp_path / "bag" / "metadata.yaml").write_text(text)
    with pytest.raises(BagReadError, match=r"bag: cannot open: "):
        open_bag(tmp_path / "bag").__enter__()
    report = salvage(tmp_path / "bag", tmp_path / "out")
    assert report.total == len(written)
    assert any("metadata.yaml: unreadable" in d for d in report.damage)
    with open_bag(tmp_path / "out") as bag:
        assert {k: bag.custom_data[k] for k in CUSTOM} == CUSTOM


def test_the_command_prints_what_was_salvaged(
    chunked: tuple[Path, list[Message]], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source, _ = chunked
    damaged = _copy(source, tmp_path / "cut")
    damaged.write_bytes(damaged.read_bytes()[: damaged.stat().st_size // 2])
    assert main(["salvage", str(tmp_path / "cut")]) == 0
    out = capsys.readouterr()
    assert "/joint_states" in out.out and "12000" in out.out  # salvaged vs recorded
    assert (tmp_path / "cut.salvaged").is_dir()
    damaged.write_bytes(damaged.read_bytes()[:100])  # not even the first chunk
    assert main(["salvage", str(tmp_path / "cut"), "--out", str(tmp_path / "none")]) == 2
    assert "nothing could be salvaged" in capsys.readouterr().err
    assert not (tmp_path / "none").exists() and not (tmp_path / "none.partial").exists()


@pytest.fixture(scope="module")
def small(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Message]]:
    path = tmp_path_factory.mktemp("small") / "bag"
    return path, _write_bag(path, 4_000)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    cut=st.floats(0.0, 1.0),
    flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.binary(min_size=1, max_size=16)), max_size=3),
)
def test_any_damage_gives_messages_or_a_clear_error(
    small: tuple[Path, list[Message]],
    tmp_path_factory: pytest.TempPathFactory,
    cut: float,
    flips: list[tuple[float, bytes]],
) -> None:
    source, written = small
    tmp = tmp_path_factory.mktemp("damage")
    damaged = _copy(source, tmp / "bag")
    data = bytearray(damaged.read_bytes())
    for where, junk in flips:
        at = round(where * (len(data) - 1))
        data[at : at + len(junk)] = junk
    data = data[: round(cut * len(data))]
    damaged.write_bytes(bytes(data))
    error = ""
    try:
        with open_bag(tmp / "bag") as bag:
            joint_series(bag, "/joint_states")
            list(bag.messages(["/load_cell"]))
    except BagReadError as err:  # the one error allowed: it names the bag
        error = str(err)
    assert not error or error.startswith(str(tmp / "bag"))
    report = salvage(tmp / "bag", tmp / "out")  # never raises on damaged data
    if report.out is None:
        assert not (tmp / "out").exists()
        return
    got = _salvaged(tmp / "out")
    assert len(got) == report.total > 0
    if not flips:  # truncation alone: only original messages
        assert set(got) <= set(written)


def test_damaged_values_sqlite_still_reads_are_skipped_by_name(tmp_path: Path) -> None:
    """Found by `make fuzz`: cells of the wrong type or with invalid UTF-8 that sqlite reads
    without complaint (they ended salvage with a TypeError or UnicodeDecodeError)."""
    written = _sqlite_bag(tmp_path / "bag", 50)
    (db,) = (tmp_path / "bag").glob("*.db3")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE messages SET timestamp = 1.5 WHERE id = 3")
        con.execute("UPDATE messages SET data = 'text, not a blob' WHERE id = 4")
        con.execute("UPDATE message_definitions SET topic_type = 42")
        con.execute("INSERT INTO topics (id, name, type, serialization_format, "
                    "offered_qos_profiles, type_description_hash) "
                    "VALUES (9, CAST(X'2FF2' AS TEXT), 42, 'cdr', '', '')")  # fmt: skip
    report = salvage(tmp_path / "bag", tmp_path / "out")
    assert _salvaged(tmp_path / "out") == [m for i, m in enumerate(written, 1) if i not in (3, 4)]
    assert "bag.db3: 2 message rows with damaged values; skipped" in report.damage
    assert any("type 42 not writable" in d for d in report.damage), report.damage


# ------------------------------------------------------------------ compressed bags (real ones)

BAGS = Path(__file__).resolve().parents[1] / "data" / "external_bags"
HUMBLE = {  # rosbag2's own test bags, humble: zstd per message and per file
    "message": ("rosbag2_humble_sqlite3_zstd_message_compression_v4",
                {"/rosout": 758, "/topic": 369}),
    "file": ("rosbag2_humble_sqlite3_zstd_file_compression_v4", {"/rosout": 392, "/topic": 383}),
}  # fmt: skip


def _strings_by_rosbags(bag: Path, topic: str) -> list[str]:
    """The /topic strings read by rosbags itself (not our reader): what any tool would see."""
    from rosbags.rosbag2 import Reader  # noqa: PLC0415

    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [store.deserialize_cdr(raw, c.msgtype).data
                for c, _t, raw in reader.messages(connections=conns)]  # fmt: skip


@pytest.mark.parametrize("mode", ["message", "file"])
def test_compressed_bags_are_salvaged_into_bags_any_reader_reads(mode: str, tmp_path: Path) -> None:
    """Salvage once kept the zstd frames and wrote "uncompressed": nothing could read it. The
    source is only read: nothing is written beside it."""
    name, counts = HUMBLE[mode]
    source = tmp_path / "source"
    shutil.copytree(BAGS / name, source)
    before = sorted(p.name for p in source.iterdir())
    report = salvage(source, tmp_path / "out")
    assert sorted(p.name for p in source.iterdir()) == before  # no -wal/-shm beside the bag
    assert report.out == tmp_path / "out" and dict(report.kept) == counts, report.damage
    assert report.damage == []
    original = _strings_by_rosbags(source, "/topic")
    assert len(original) == counts["/topic"]
    assert _strings_by_rosbags(tmp_path / "out", "/topic") == original


def test_a_truncated_compressed_file_keeps_what_decompresses(tmp_path: Path) -> None:
    name, _ = HUMBLE["file"]
    bag = tmp_path / "bag"
    shutil.copytree(BAGS / name, bag)
    first = sorted(bag.glob("*.db3.zstd"))[0]
    data = first.read_bytes()
    first.chmod(0o644)
    first.write_bytes(data[: len(data) * 2 // 3])
    report = salvage(bag, tmp_path / "out")
    assert report.out is not None and 0 < report.total < 775
    assert any(d.startswith(f"{first.name}: zstd stream cut inside a frame") for d in report.damage)
    with open_bag(tmp_path / "out") as out:  # proven readable
        assert sum(1 for _ in out.messages(list(report.kept))) == report.total


def test_a_payload_that_does_not_decompress_is_left_out_and_counted(tmp_path: Path) -> None:
    name, counts = HUMBLE["message"]
    bag = tmp_path / "bag"
    shutil.copytree(BAGS / name, bag)
    first = sorted(bag.glob("*.db3"))[0]
    first.chmod(0o644)
    with sqlite3.connect(first) as db:
        (topic_id,) = db.execute("SELECT id FROM topics WHERE name = '/topic'").fetchone()
        (row,) = db.execute(
            "SELECT min(id) FROM messages WHERE topic_id = ?", (topic_id,)
        ).fetchone()
        db.execute("UPDATE messages SET data = ? WHERE id = ?", (b"\x28\xb5\x2f\xfdgarbage", row))
    report = salvage(bag, tmp_path / "out")
    assert report.kept["/topic"] == counts["/topic"] - 1 and report.kept["/rosout"] == 758
    assert any(d.startswith("topic /topic: 1 message(s) do not decompress") for d in report.damage)
