"""The timed recording session (so101.stack.record_session): the schedule lerobot-record keeps (episodes
of a fixed length, a reset period between them and none after the last), its keys (right arrow,
left arrow, Esc) at every phase, and the bytes a terminal sends for them."""

from __future__ import annotations

from so101.stack.record_session import Key, Session, decode_keys


def events(actions) -> list[str]:
    return [action.recorder for action in actions if action.recorder]


def session(episodes: int = 2) -> Session:
    return Session(episodes=episodes, episode_time=10.0, reset_time=5.0)


def test_episodes_end_on_their_time_limit_with_a_reset_period_between_and_none_after_the_last():
    s = session()
    begun = s.begin(0.0)
    assert events(begun) == ["start"]
    assert any(action.reset_sim for action in begun), "the sim is reset before each episode"
    assert s.tick(9.9) == []
    assert events(s.tick(10.0)) == ["stop"]
    assert s.tick(14.9) == []
    assert events(s.tick(15.0)) == ["start"]
    assert events(s.tick(25.0)) == ["stop"]
    assert s.done and s.recorded == 2
    assert s.tick(100.0) == [] and s.key(Key.NEXT, 100.0) == []


def test_an_episode_s_time_counts_from_when_its_recording_began():
    s = session()
    s.begin(0.0)
    s.started_at(2.0)  # the recorder answered the start 2 s later
    assert s.tick(11.9) == []
    assert events(s.tick(12.0)) == ["stop"]
    s.started_at(13.0)  # in the reset period: no episode to time
    assert events(s.tick(17.0)) == ["start"]


def test_right_arrow_ends_the_episode_or_the_reset_now():
    s = session()
    s.begin(0.0)
    assert events(s.key(Key.NEXT, 3.0)) == ["stop"]
    assert events(s.key(Key.NEXT, 4.0)) == ["start"]
    assert s.tick(13.9) == [], "the new episode runs its full time from its start"
    assert events(s.tick(14.0)) == ["stop"] and s.done


def test_left_arrow_during_an_episode_drops_it_and_records_it_again_after_the_reset():
    s = session(episodes=1)
    s.begin(0.0)
    assert events(s.key(Key.RERECORD, 2.0)) == ["discard"]
    assert not s.done and s.recorded == 0
    assert events(s.tick(7.0)) == ["start"], "re-recorded after the reset period"
    assert events(s.tick(17.0)) == ["stop"] and s.done and s.recorded == 1


def test_left_arrow_in_the_reset_period_drops_the_episode_just_recorded_once():
    s = session()
    s.begin(0.0)
    s.tick(10.0)
    assert s.recorded == 1
    assert events(s.key(Key.RERECORD, 11.0)) == ["discard_last"]
    assert s.recorded == 0
    assert s.key(Key.RERECORD, 12.0) == [], "only the episode just recorded can be dropped"
    assert events(s.tick(15.0)) == ["start"]
    s.tick(25.0)
    s.tick(30.0)
    s.tick(40.0)
    assert s.done and s.recorded == 2


def test_esc_keeps_the_running_episode_and_stops():
    s = session(episodes=5)
    s.begin(0.0)
    assert events(s.key(Key.STOP, 4.0)) == ["stop"]
    assert s.done and s.recorded == 1
    s = session(episodes=5)
    s.begin(0.0)
    s.tick(10.0)
    assert events(s.key(Key.STOP, 11.0)) == [], "nothing is recording in the reset period"
    assert s.done and s.recorded == 1


def test_terminal_bytes_become_keys():
    assert decode_keys(b"\x1b[C") == [Key.NEXT]
    assert decode_keys(b"\x1bOD") == [Key.RERECORD]
    assert decode_keys(b"\x1b") == [Key.STOP]
    assert decode_keys(b"\x1b[C\x1b[D\x1b") == [Key.NEXT, Key.RERECORD, Key.STOP]
    # Up arrow, F5, letters: not session keys.
    assert decode_keys(b"\x1b[A\x1b[15~xyz") == []
    assert decode_keys(b"\x1b\x1b[C") == [Key.STOP, Key.NEXT]


def test_without_a_count_episodes_go_on_until_esc():
    s = Session(episodes=0, episode_time=1.0, reset_time=1.0)
    said = [action.say for action in s.begin(0.0) if action.say]
    assert said == ["recording episode 1 (1 s)"]
    now = 0.0
    for _ in range(10):
        now += 1.0
        s.tick(now)
    assert not s.done and s.recorded == 5
    s.key(Key.STOP, now)
    assert s.done
