"""Whole live episodes to success in headless Chromium, played by a scripted participant through the page: a
study of three seeds x two agents (``live toxic-waste --study``, at ``--speed 3``) in which the participant reads
the streamed state, walks to each ball with the arrow keys (following the lab's human routes through the
passages), picks it up, walks to the robot's area and drops it into the container, answers every "Where are
you?" by typing the name of its area, and fills in the questionnaire after each episode. Then the study folder
is checked: six rows of ``study.csv``, all successes, every drop's outcome logged, questions paced.

``LIVE_SCREENSHOTS=DIR`` keeps screenshots of the labelled map, a question and the end screen (docs/live.md's).
Deadlines count the page's simulated seconds (``live_harness.py``; at ``--speed 3``, three per wall second).
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from live_harness import LiveServer, SimClock

from embodied_adhoc.comms.vocabulary import NODE_NAMES
from embodied_adhoc.live.humans import walkable
from embodied_adhoc.sim.lab_layout import LAB_LAYOUT

pytestmark = pytest.mark.slow

CHROMIUM, DRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
SPEED = 3.0
ESCAPE_AFTER = 30.0  # simulated s without a step closer to the point before the walker tries a spot nearby
PLAN = {
    "episodes": [{"agent": agent, "seed": seed} for agent in ("hotspot", "known-task") for seed in (0, 1, 2)],
    "questionnaire": [
        {"id": "understood", "text": "The robot understood where I was.", "scale": 5},
        {"id": "helpful", "text": "The robot was a helpful teammate.", "scale": 7},
    ],
    "max_steps": 100,
}
KEYS = {"up": "\ue013", "down": "\ue015", "left": "\ue012", "right": "\ue014"}  # selenium's arrow keys


@pytest.fixture
def study_server(tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(PLAN))
    server = LiveServer(["--study", str(plan), "--out", str(tmp_path / "study"), "--speed", str(SPEED)])
    yield server, server.url, tmp_path / "study"
    server.kill()


@pytest.fixture
def browser():
    if not (Path(CHROMIUM).is_file() and Path(DRIVER).is_file()):
        pytest.fail(
            "Debian's chromium and chromium-driver are needed: run scripts/bootstrap.sh (it installs them)"
        )
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for argument in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        "--disable-dev-shm-usage",
        "--window-size=1240,1000",
        "--autoplay-policy=no-user-gesture-required",
    ):
        options.add_argument(argument)
    driver = webdriver.Chrome(options=options, service=Service(DRIVER))
    yield driver
    driver.quit()


class ScriptedParticipant:
    """Drives the page as a person would: arrow keys, the act key, the reply box, the questionnaire."""

    def __init__(self, driver, shots: Path | None):
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.by import By

        self.driver, self.shots, self.by, self.chains = driver, shots, By, ActionChains
        self.held: set[str] = set()
        self.answers = 0
        self.shot_question = False
        self.clock = SimClock(driver)
        self.rng = np.random.default_rng(0)  # the escape spots (ScriptedParticipant._escape_spot)

    def stats(self, expression: str):
        return self.driver.execute_script(f"return window.liveStats.{expression};")

    def state(self) -> dict:
        state = self.stats("lastState")
        if state:
            self.clock.observe(state["sim_time"])
        return state

    def hold(self, keys: set[str]) -> None:
        if keys == self.held:
            return
        chain = self.chains(self.driver)
        for key in self.held - keys:
            chain.key_up(KEYS[key])
        for key in keys - self.held:
            chain.key_down(KEYS[key])
        chain.perform()
        self.held = set(keys)

    def answer_if_asked(self) -> None:
        box = self.driver.find_element(self.by.ID, "reply-text")
        if box.get_attribute("disabled"):
            return
        self.hold(set())
        if self.shots and not self.shot_question:
            self.driver.save_screenshot(str(self.shots / "live_asking.png"))
            self.shot_question = True
        from selenium.common.exceptions import ElementNotInteractableException

        try:
            box.send_keys(f"I'm at the {NODE_NAMES[self.state()['human_node']]}")
            self.driver.find_element(self.by.ID, "reply-send").click()
        except ElementNotInteractableException:
            # The question closed (answered by timeout or withdrawn) between the check and the typing: the
            # robot asks again and the walker answers then.
            return
        self.answers += 1
        time.sleep(0.2)

    def walk_to(
        self, point, area: int, close: float, give_up: float = 360.0, ball: int | None = None
    ) -> bool:
        """Follow the human route to ``area``, then walk straight towards ``point`` until within ``close`` m
        (``give_up``: simulated seconds); True when there. False, without arriving, once the episode is over
        (the simulation then stands still) or ``ball`` is no longer on the floor (it was seen on the floor while
        still falling into the container)."""
        deadline = self.clock.deadline(give_up, f"the walker to reach {point} in area {area}")
        lead = 1.2 * SPEED * 0.15 + 0.1  # m the walker still moves after a key is released (page latency)
        waypoints: list = []
        planned_from = None
        stuck_since, last = self.clock.elapsed, None
        # No step closer to the point for ESCAPE_AFTER simulated s (blocked where walking round the robot does not
        # help, or going to and fro across an area's border as the plan flips): walk to a random spot nearby,
        # then plan afresh.
        nearest, nearest_at, escape = np.inf, self.clock.elapsed, None
        while True:
            self.answer_if_asked()
            state = self.state()
            if self.stats("done") is not None or (ball is not None and state["balls"][ball] != 0):
                self.hold(set())
                return False
            deadline.check(f": state {state}", read=False)
            here = np.array(state["human"])
            distance = float(np.hypot(*(np.array(point, dtype=float) - here)))
            if distance < nearest - 0.3:
                nearest, nearest_at = distance, self.clock.elapsed
            elif escape is None and self.clock.elapsed - nearest_at > ESCAPE_AFTER:
                escape = (self._escape_spot(here), self.clock.elapsed)
            if escape is not None:
                spot, since = escape
                if np.abs(spot - here).max() < max(0.3, lead) or self.clock.elapsed - since > 3 * SPEED:
                    escape, planned_from = None, None  # there (or as near as it gets): plan afresh
                    nearest, nearest_at = distance, self.clock.elapsed
                    continue
                self.hold(self._keys_towards(spot - here, lead))
                time.sleep(0.03)
                continue
            if state["human_node"] != planned_from:  # (re)plan from the area the walker is in
                planned_from = state["human_node"]
                waypoints = [np.array(p) for p in LAB_LAYOUT.route(planned_from, area, spots="human")[:-1]]
                waypoints.append(np.array(point, dtype=float))
            target = waypoints[0]
            offset = target - here
            final = len(waypoints) == 1
            if final and state["human_node"] == area and np.hypot(*offset) < close:
                self.hold(set())
                return True
            if not final and np.abs(offset).max() < max(0.3, lead):
                waypoints.pop(0)
                continue
            keys = self._keys_towards(offset, lead)
            if last is None or np.hypot(*(here - last)) > 0.05:
                stuck_since, last = self.clock.elapsed, here
            elif self.clock.elapsed - stuck_since > SPEED:  # blocked (the robot in the way): walk round it
                waypoints[:0] = self._round_the_robot(here, target, np.array(state["robot"]))
                stuck_since = self.clock.elapsed
                continue
            self.hold(keys)
            time.sleep(0.03)

    @staticmethod
    def _keys_towards(offset, lead: float) -> set[str]:
        """The arrow keys that move the walker along ``offset`` (each axis beyond half the lead)."""
        keys = set()
        if offset[0] > lead / 2:
            keys.add("right")
        elif offset[0] < -lead / 2:
            keys.add("left")
        if offset[1] > lead / 2:
            keys.add("up")
        elif offset[1] < -lead / 2:
            keys.add("down")
        return keys

    def _escape_spot(self, here) -> np.ndarray:
        """A spot a person can stand on 1-2 m from ``here`` (the participant's own seeded draws)."""
        for _ in range(200):
            angle, reach = self.rng.uniform(0.0, 2 * np.pi), self.rng.uniform(1.0, 2.0)
            spot = here + reach * np.array([np.cos(angle), np.sin(angle)])
            if walkable(LAB_LAYOUT, spot):
                return spot
        return here

    @staticmethod
    def _round_the_robot(here, target, robot) -> list:
        """Waypoints round the robot: beside the walker, across its way and away from the robot, then past it
        (points a person can stand on)."""
        way = (target - here) / max(float(np.hypot(*(target - here))), 1e-9)
        across = np.array([-way[1], way[0]])
        if across @ (here - robot) < 0:
            across = -across
        for side in (across, -across, -way):
            for reach in (0.9, 0.6, 0.3):
                beside = here + reach * side
                if walkable(LAB_LAYOUT, beside):
                    past = beside + 1.3 * way  # then on past the robot, if a person can stand there
                    return [beside, past] if walkable(LAB_LAYOUT, past) else [beside]
        return [here - 0.3 * way]

    def act(self) -> None:
        """The act key, once the walker's previous motion has finished (keys wait for it: a press during it
        is refused with a notice)."""
        self.hold(set())
        deadline = self.clock.deadline(60, "the walker's motion to finish")
        while self.state()["busy"]:
            if self.stats("done") is not None:
                return  # the episode ended mid-motion: nothing to press (press reads the done event)
            deadline.check(read=False)
            self.answer_if_asked()
            time.sleep(0.05)
        self.chains(self.driver).send_keys("e").perform()

    def outcomes(self, kind: str) -> list[dict]:
        return [o for o in self.stats("outcomes") if o["kind"] == kind]

    def press(self, kind: str) -> dict | None:
        """The act key and the outcome of the pick or drop it started; None if the press was refused (the
        notice says why: too far from the ball, the robot not in the area), after which the participant tries
        again."""
        before = len(self.outcomes(kind))
        self.act()
        deadline = self.clock.deadline(120, f"a {kind} outcome")
        while True:
            self.answer_if_asked()
            outcomes, state = self.outcomes(kind), self.state()
            if self.stats("done") is not None:
                return None  # the episode ended (play_episode reads how)
            deadline.check(f": state {state}", read=False)
            if len(outcomes) > before and (
                not outcomes[-1]["succeeded"]
                or state["holding"] == (outcomes[-1]["ball"] if kind == "pick" else None)
            ):  # (the event comes before the next frame's state shows it)
                return outcomes[-1]
            if len(outcomes) == before and not state["busy"] and deadline.passed(read=False) > 3 * SPEED:
                return None  # no motion started
            time.sleep(0.05)

    def play_episode(self) -> dict:
        """Collect every ball on the floor into the container; the episode's done event."""
        picks = drops = refused = 0
        deadline = self.clock.deadline(720, "the episode to finish")
        while self.stats("done") is None:
            self.answer_if_asked()
            state = self.state()
            deadline.check(f": state {state}", read=False)
            if state["holding"] is None:
                floor = [i for i, s in enumerate(state["balls"]) if s == 0]
                if not floor:
                    time.sleep(0.1)
                    continue
                here = np.array(state["human"])
                ball = min(floor, key=lambda i: np.hypot(*(np.array(state["ball_xy"][i]) - here)))
                xy = state["ball_xy"][ball]
                if not self.walk_to(xy, LAB_LAYOUT.node_at(xy), close=0.5, ball=ball):
                    continue
                outcome = self.press("pick")
                if outcome is None:
                    refused += 1
                    assert refused < 10, f"pick refused ten times: {self.state()}"
                    continue
                picks += 1
                assert outcome["succeeded"], outcome
            else:
                robot_area = state["robot_node"]
                if not self.walk_to(LAB_LAYOUT.human_spots[robot_area], robot_area, close=1.5):
                    continue
                if self.state()["robot_node"] != self.state()["human_node"]:
                    continue  # the robot moved on: follow it
                outcome = self.press("drop")
                if outcome is None:  # the robot left the area just before the key press
                    refused += 1
                    assert refused < 10, f"drop refused ten times: {self.state()}"
                    continue
                drops += 1
                assert outcome["succeeded"], outcome  # the robot holds still during a hand-over
        return self.stats("done")

    def questionnaire(self) -> None:
        for item in PLAN["questionnaire"]:
            self.driver.find_element(self.by.ID, f"{item['id']}-{item['scale'] - 1}").click()
        self.driver.find_element(self.by.ID, "survey-send").click()


def test_a_scripted_participant_finishes_a_study_of_three_seeds_and_two_agents(study_server, browser):
    server, url, study = study_server
    shots = Path(os.environ["LIVE_SCREENSHOTS"]) if os.environ.get("LIVE_SCREENSHOTS") else None
    if shots:
        shots.mkdir(parents=True, exist_ok=True)
    person = ScriptedParticipant(browser, shots)
    person.clock.context = server.tail
    by = person.by
    browser.get(url)
    seen = []
    for position in range(1, 7):
        person.clock.wait(
            lambda position=position: (
                browser.execute_script("return window.liveStats.studyPosition") == position
            ),
            60,
            f"episode {position} to be offered",
        )
        assert "Walk with the arrow keys" in browser.find_element(by.ID, "instructions").text
        places = [b.text for b in browser.find_elements(by.CSS_SELECTOR, "#place-buttons button")]
        assert places == list(NODE_NAMES)
        browser.find_element(by.ID, "start").click()
        person.clock.wait(lambda: person.stats("lastState"), 30, "frames")
        if shots and position == 1:
            time.sleep(0.5)
            browser.save_screenshot(str(shots / "live_map.png"))
        done = person.play_episode()
        assert done["outcome"] == "success", done
        seen.append(done)
        if shots and position == 1:
            browser.save_screenshot(str(shots / "live_end.png"))
        person.questionnaire()
    person.clock.wait(
        lambda: browser.execute_script("return window.liveStats.studyComplete === true"),
        30,
        "the study to complete",
    )
    assert person.answers >= 1
    output = server.interrupt()
    assert "Traceback" not in output, output

    folder = study / "P001"
    with open(folder / "study.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 6 and all(row["outcome"] == "success" for row in rows)
    assert sorted((row["agent"], row["seed"]) for row in rows) == sorted(
        (e["agent"], str(e["seed"])) for e in PLAN["episodes"]
    )
    assert all(row["understood"] == "4" and row["helpful"] == "6" for row in rows)
    assert all(int(row["drops"]) == 3 and row["drops_failed"] == "0" for row in rows), rows
    for row in rows:
        events = [
            json.loads(line) for line in (folder / row["folder"] / "events.jsonl").read_text().splitlines()
        ]
        metrics = json.loads((folder / row["folder"] / "metrics.json").read_text())
        assert metrics["outcome"] == "success" and (folder / row["folder"] / "episode.rrd").is_file()
        drops = [e for e in events if e["kind"] == "drop"]
        assert len(drops) == 3 and all(d["succeeded"] and "dropped ball" in d["result"] for d in drops)
        # the container count never drops
        disposed = [sum(s == "container" for s in e["states"]) for e in events if e["kind"] == "balls"]
        assert disposed == sorted(disposed) and disposed[-1] == 3
        # no question while one is open: every question but the last was answered or timed out before the next
        questions = [e for e in events if e["kind"] == "question"]
        answered = [e for e in events if e["kind"] == "reply" and e["result"] == "answered"]
        assert len(questions) <= len(answered) + 1
    text = subprocess.run(
        [sys.executable, "-m", "embodied_adhoc.cli", "live", "summarise", str(study)],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    assert "6 episodes of 1 participants" in text and "hotspot" in text and "known-task" in text
