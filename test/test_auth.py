"""Shared-key signatures (issue 9, deliverable 5): key files are checked line by line, a signature
holds only for its body, channel and key, counters refuse replays and stale messages, records and
timed paths are signed and checked through the nodes' helper (fleet_planner/ros/signing.py)."""
import os

import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path

from fleet_planner.auth import AuthError, Signer, Verifier, load_keys, new_key_line
from fleet_planner.ros.signing import Keys, PathPairing, path_digest
from msg_schemas.records import PathAuth, RecordError, Task, TaskEvent

SECRET = "ab" * 32


def key_file(tmp_path, text, name="keys", mode=0o600):
    path = tmp_path / name
    path.write_text(text)
    os.chmod(path, mode)
    return path


@pytest.mark.parametrize(("text", "words"), [
    ("k1\n", ":1: expected '<key id> <secret in hex>'"),
    (f"k/1 {SECRET}\n", ":1: key id must be"),
    ("k1 zz" + "0" * 62 + "\n", "the secret must be hex digits"),
    ("k1 abcd\n", "at least 32 bytes"),
    (f"k1 {SECRET}\nk1 {SECRET}\n", ":2: key 'k1' given twice"),
    ("# nothing\n", "no key in the file"),
])
def test_bad_key_files_are_refused_naming_the_line(tmp_path, text, words):
    with pytest.raises(AuthError, match=words):
        load_keys(key_file(tmp_path, text))


def test_a_key_file_others_may_read_is_refused(tmp_path):
    with pytest.raises(AuthError, match="chmod 600"):
        load_keys(key_file(tmp_path, f"k1 {SECRET}\n", mode=0o644))


def test_key_lines_made_by_the_tool_load(tmp_path):
    keys = load_keys(key_file(tmp_path, f"# comment\n{new_key_line('ops-1')}  # trailing\n{new_key_line('ops.2')}\n"))
    assert list(keys) == ["ops-1", "ops.2"] and all(len(s) == 32 for s in keys.values())


class Clock:
    def __init__(self, t=10**18):
        self.t = t

    def __call__(self):
        return self.t


def test_a_signature_holds_only_for_its_body_channel_and_key_once():
    clock = Clock()
    signer = Signer("k1", bytes.fromhex(SECRET), clock)
    verifier = Verifier({"k1": bytes.fromhex(SECRET), "k2": b"x" * 32}, clock=clock)
    auth = signer.sign("/fleet/tasks", "body")
    assert verifier.problem("/fleet/tasks", "tampered", auth) == "wrong signature"
    assert verifier.problem("/other", "body", auth) == "wrong signature"
    assert verifier.problem("/fleet/tasks", "body", {**auth, "key": "k2"}) == "wrong signature"
    assert "does not accept" in verifier.problem("/fleet/tasks", "body", {**auth, "key": "k9"})
    assert "unsigned" in verifier.problem("/fleet/tasks", "body", None)
    assert verifier.problem("/fleet/tasks", "body", auth) is None
    assert "replayed" in verifier.problem("/fleet/tasks", "body", auth)
    assert verifier.problem("/fleet/tasks", "next", signer.sign("/fleet/tasks", "next")) is None
    clock.t += 10**12  # 1000 s later, a message signed back then is stale
    old = Signer("k1", bytes.fromhex(SECRET), lambda: 10**18 - 1)
    assert "s from this node's clock" in verifier.problem("/x", "body", old.sign("/x", "body"))
    assert verifier.refused == {"bad signature": 3, "unknown key": 1, "unsigned": 1, "replay": 1, "stale": 1}
    assert verifier.total_refused == 7


def test_counters_grow_even_when_the_clock_stands_still():
    signer = Signer("k1", bytes.fromhex(SECRET), Clock())
    assert [signer.sign("c", "b")["ctr"] for _ in range(3)] == [10**18, 10**18 + 1, 10**18 + 2]


def test_records_are_signed_and_checked_by_the_nodes_helper(tmp_path):
    planner_key = key_file(tmp_path, f"planner-1 {SECRET}\n", "planner.key")
    other = key_file(tmp_path, new_key_line("intruder") + "\n", "other.key")
    signer, checker, forger = Keys(sign_file=str(planner_key)), Keys(trust_file=str(planner_key)), \
        Keys(sign_file=str(other))
    ev = TaskEvent(task_id="J1", event="cancelled", stamp=1.0, robot_id="r1")
    signed = signer.sign(ev, "/fleet/task_events")
    assert TaskEvent.from_json(signed.to_json()) == signed and signed.auth["key"] == "planner-1"
    assert checker.problem(TaskEvent.from_json(signed.to_json()), "/fleet/task_events") is None
    assert checker.problem(ev, "/fleet/task_events").startswith("unsigned")
    assert checker.problem(forger.sign(ev, "/fleet/task_events"), "/fleet/task_events") == \
        "signed with a key this node does not accept"
    assert checker.refused == 2
    with pytest.raises(RecordError, match="task.auth.mac"):
        Task.from_json('{"schema": "fleet/task@1", "id": "a", "pick": "b", "place": "c", '
                       '"auth": {"key": "k", "ctr": 1, "mac": "xyz"}}')


def path(*xs):
    msg = Path()
    msg.header.frame_id = "map"
    msg.header.stamp.sec = 7
    for i, x in enumerate(xs):
        p = PoseStamped()
        p.header.stamp.sec = 7 + i
        p.pose.position.x = float(x)
        msg.poses.append(p)
    return msg


def test_a_timed_path_is_followed_only_with_its_signed_digest(tmp_path):
    planner_key = key_file(tmp_path, f"planner-1 {SECRET}\n", "planner.key")
    signer, checker = Keys(sign_file=str(planner_key)), Keys(trust_file=str(planner_key))
    channel = "/robots/r1/timed_path_auth"
    good = path(1, 2, 3)
    assert path_digest(good) == path_digest(path(1, 2, 3)) != path_digest(path(1, 2, 4))
    pairing = PathPairing(checker, "r1", channel)
    assert pairing.offer_path(good) is None                       # waits for its signature
    assert pairing.offer_auth(signer.path_auth(good, "r1", channel)) is good
    tampered = path(1, 2, 9)                                       # same stamp, other poses
    assert pairing.offer_auth(signer.path_auth(good, "r1", channel)) is None
    assert pairing.offer_path(tampered) is None and "does not match its signed digest" in pairing.problem
    assert pairing.offer_auth(signer.path_auth(good, "r2", channel)) is None and "not this robot" in pairing.problem
    unsigned = PathAuth(robot_id="r1", path_id=7 * 10**9, digest=path_digest(good))
    assert pairing.offer_auth(unsigned) is None and "unsigned" in pairing.problem
