"""A recording killed with SIGKILL loses at most its last chunk, and `mows bag repair` rebuilds a
bag that reads and replays. The writer is a real process killed by the kernel, at a
chunk boundary and in the middle of one."""

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from mcap_records import assert_jazzy
from mows.cli.main import main
from mows.device.recording import bag_repair, bags

STRING = "std_msgs/msg/String"
# The child: writes numbered messages of 10 kB into a Recording, says on stdout how many it had
# written each time a chunk reached the disk, and after ``stop_after`` messages waits to be killed.
CHILD = textwrap.dedent("""
    import sys, time
    from mows.device.recording import bags
    path, stop_after = sys.argv[1], int(sys.argv[2])
    store = bags.typestore()
    recording = bags.Recording(path, {"/chatter": ("std_msgs/msg/String", [])})
    chunks = 0
    for i in range(stop_after):
        message = store.types["std_msgs/msg/String"](data=f"{i:06d}" + "x" * 10000)
        recording.write("/chatter", store.serialize_cdr(message, "std_msgs/msg/String"), 1_000_000 + i)
        if recording._flushed_chunks != chunks:
            chunks = recording._flushed_chunks
            print("flushed", i + 1, flush=True)
    print("waiting", flush=True)
    time.sleep(600)
""")


def killed_recording(path, stop_after):
    """Run the child until it waits, SIGKILL it; the message counts of its flushes."""
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path), str(stop_after)], stdout=subprocess.PIPE, text=True
    )
    flushed = []
    for line in child.stdout:
        if line.startswith("flushed"):
            flushed.append(int(line.split()[1]))
        if line.startswith("waiting"):
            break
    child.send_signal(signal.SIGKILL)
    child.wait(timeout=60)
    assert child.returncode == -signal.SIGKILL
    return flushed


def numbers(path):
    return [int(m.message.data[:6]) for m in bags.read_bag(path)]


@pytest.mark.parametrize("stop_after", [210, 250])  # 210: just after a chunk closed; 250: mid-chunk
def test_a_killed_recording_is_repaired_from_its_intact_chunks(tmp_path, capsys, stop_after):
    bag = tmp_path / "recording"
    flushed = killed_recording(bag, stop_after)
    assert len(flushed) >= 2
    with pytest.raises(bags.BagError, match="mows bag repair"):
        list(bags.read_bag(bag))
    assert main(["bag", "repair", str(bag)]) == 0
    out = capsys.readouterr().out
    assert f"recovered {flushed[-1]} messages" in out
    assert f"all {flushed[-1]} messages on disk at the recorder's last flush were recovered" in out
    # Every message up to the last flushed chunk, in order, none made up; at most one chunk lost.
    assert numbers(bag) == list(range(flushed[-1]))
    assert_jazzy(bag)
    assert stop_after - flushed[-1] <= flushed[-1] - flushed[-2]
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "recording.mcap", "recording.mcap.damaged"]
    assert main(["bag", "repair", str(bag)]) == 2  # a bag that reads is left alone


def test_a_chunk_cut_on_disk_is_dropped_and_said(tmp_path, capsys):
    bag = tmp_path / "recording"
    flushed = killed_recording(bag, 250)
    mcap = bag / "recording.mcap"
    whole = mcap.read_bytes()
    mcap.write_bytes(whole[: len(whole) - 100_000])  # the last chunk record torn (a write cut by the kill)
    found = bag_repair.salvage(mcap)
    assert found.messages and not found.closed and "cut short" in found.problem
    assert main(["bag", "repair", str(bag)]) == 0
    out = capsys.readouterr().out
    assert f"{flushed[-1] - flushed[-2]} of the {flushed[-1]} messages on disk" in out and "cut short" in out
    assert numbers(bag) == list(range(flushed[-2]))
    assert (bag / "recording.mcap.damaged").read_bytes() == whole[: len(whole) - 100_000]  # nothing deleted


def test_a_closed_recording_reads_without_repair(tmp_path):
    bag = tmp_path / "recording"
    store = bags.typestore()
    recording = bags.Recording(bag, {"/chatter": (STRING, [])})
    for i in range(5):
        recording.write("/chatter", store.serialize_cdr(store.types[STRING](data=f"{i:06d}"), STRING), i)
    recording.close()
    assert numbers(bag) == list(range(5))
    with pytest.raises(bags.BagError, match="exists"):
        bags.Recording(bag, {"/chatter": (STRING, [])})


def test_an_empty_directory_and_a_foreign_file_are_no_bag(tmp_path):
    with pytest.raises(bags.BagError, match="not a rosbag2 bag"):
        list(bags.read_bag(tmp_path))
    other = tmp_path / "notes.mcap"
    other.write_bytes(b"just text")
    with pytest.raises(bags.BagError, match="not an MCAP file"):
        bag_repair.salvage(other)
    assert os.path.getsize(other) == 9


# The repair, killed at each step of its swap: after the damaged file is renamed, after the
# rebuilt one is moved in. No clean-up runs (SIGKILL).
KILLED_REPAIR = textwrap.dedent("""
    import os, shutil, signal, sys
    from pathlib import Path
    from mows.device.recording import bag_repair
    step = sys.argv[2]
    if step == "rename":
        rename = Path.rename
        def killing_rename(self, target):
            rename(self, target)
            os.kill(os.getpid(), signal.SIGKILL)
        Path.rename = killing_rename
    else:
        move = shutil.move
        def killing_move(source, target):
            move(source, target)
            os.kill(os.getpid(), signal.SIGKILL)
        bag_repair.shutil.move = killing_move
    bag_repair.repair(sys.argv[1])
""")


@pytest.mark.parametrize("step", ["rename", "move"])
def test_a_repair_killed_midway_is_undone_and_the_next_one_finishes(tmp_path, capsys, step):
    bag = tmp_path / "recording"
    flushed = killed_recording(bag, 250)
    run = subprocess.run([sys.executable, "-c", KILLED_REPAIR, str(bag), step], timeout=300)
    assert run.returncode == -signal.SIGKILL
    assert (tmp_path / ".recording.repairing").is_dir()  # what the kill left
    if step == "rename":  # no recording under its name: reading says to repair (moved: it reads)
        with pytest.raises(bags.BagError, match="mows bag repair"):
            list(bags.read_bag(bag))
    # and the repair finishes the job: no loop between the two.
    assert main(["bag", "repair", str(bag)]) == 0
    assert f"recovered {flushed[-1]} messages" in capsys.readouterr().out
    assert numbers(bag) == list(range(flushed[-1]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recording"]
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "recording.mcap", "recording.mcap.damaged"]
