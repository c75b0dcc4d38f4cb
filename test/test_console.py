"""The web operator console (fleet_planner/ros/console) in a real headless browser: Debian's
Chromium driven by Selenium through its chromedriver (scripts/setup.sh installs both), against
the in-process test fleet of test_ros_system (real nodes, real DDS) spinning in a thread. The page
loads and draws the warehouse and the robots, a job submitted from its form is done (the robots
are seen moving on the page), and its pause and e-stop buttons take effect on the robots' own
reports. Every wait is bounded."""
import asyncio
import json
import math
import shutil
import threading
import time

import pytest
from rclpy.parameter import Parameter
from test_ros_system import MEMBERS, PARKING, WH, running_fleet

from fleet_planner.ros.console import ConsoleNode, ConsoleServer

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
WAIT = 60.0  # wall seconds any one wait may take


def until(condition, timeout=WAIT, what="condition"):
    """Poll ``condition()`` (the fleet spins in its own thread) until it holds; bounded."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


@pytest.fixture(scope="module")
def console(ros_context):
    """The test fleet with a console node on its executor, spun in a thread, and the page's URL."""
    for fleet in running_fleet(ros_context):
        node = ConsoleNode(context=ros_context, warehouse=WH,
                           parking=[(PARKING[i], PARKING[i + 1]) for i in range(0, len(PARKING), 2)],
                           parameter_overrides=[Parameter("use_sim_time", value=True)])
        fleet.executor.add_node(node)
        server = ConsoleServer(node, "127.0.0.1", 0, rate_hz=5.0)
        url = server.start()
        spinner = threading.Thread(target=fleet.executor.spin, daemon=True)
        spinner.start()
        try:
            yield fleet, node, url
        finally:
            server.stop()
            fleet.executor.shutdown()
            spinner.join(timeout=10)
            fleet.executor.remove_node(node)
            node.destroy_node()


@pytest.fixture(scope="module")
def browser(console):
    if not (CHROMIUM and CHROMEDRIVER):
        pytest.fail("chromium and chromedriver are needed (scripts/setup.sh installs Debian's chromium and "
                    "chromium-driver)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1000", "--no-first-run", "--disable-extensions"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_page_load_timeout(WAIT)
    try:
        driver.get(console[2])
        until(lambda: driver.find_element("id", "conn").text == "live", what="the websocket")
        until(lambda: len(robots_on_page(driver)) == len(MEMBERS), what="every robot on the map")
        yield driver
    finally:
        driver.quit()


def robots_on_page(driver):
    """Each robot the page draws: id -> (x, y, mode, flags) from its SVG element."""
    rows = driver.execute_script(
        "return [...document.querySelectorAll('g.robot')].map(g => [g.id.slice(6), +g.dataset.x, +g.dataset.y,"
        " g.dataset.mode, g.dataset.paused, g.dataset.estop])")
    return {r[0]: tuple(r[1:]) for r in rows}


def job_state(driver, job_id):
    return driver.execute_script(f"const r = document.getElementById('job-{job_id}'); return r && r.dataset.state")


def click(driver, css):
    driver.find_element("css selector", css).click()


def submit_from_page(driver, job_id, pick="chute_1", place="B01-01"):
    from selenium.webdriver.support.ui import Select

    Select(driver.find_element("id", "f-pick")).select_by_value(pick)
    Select(driver.find_element("id", "f-place")).select_by_value(place)
    box = driver.find_element("id", "f-id")
    box.clear()
    box.send_keys(job_id)
    click(driver, "#f-submit")


def test_the_page_loads_and_draws_the_warehouse_and_every_robot(browser):
    until(lambda: browser.find_element("id", "conn").text == "live", what="the websocket")
    assert "operator console" in browser.title
    until(lambda: len(robots_on_page(browser)) == len(MEMBERS), what="every robot on the map")
    assert browser.execute_script("return document.querySelectorAll('g.station').length") == len(WH.stations)
    blocked = browser.execute_script("return document.querySelector('#layer-map path').getAttribute('d').length")
    assert blocked > 100, "the shelves are drawn"
    for rid, (x, y, *_rest) in robots_on_page(browser).items():
        member = next(m for m in MEMBERS if m.id == rid)
        assert math.dist((x, y), (member.x, member.y)) < 0.5


def test_a_job_submitted_from_the_page_is_done_and_the_robots_move_on_the_page(browser, console):
    fleet = console[0]
    before = robots_on_page(until(lambda: browser if robots_on_page(browser) else None))
    submit_from_page(browser, "WEB1", "chute_2", "B03-01")
    until(lambda: "WEB1" in fleet.monitor.last_event, what="the planner hears the job")
    until(lambda: any(math.dist(p[:2], before[r][:2]) > 0.5 for r, p in robots_on_page(browser).items()),
          what="a robot moving on the page")
    until(lambda: job_state(browser, "WEB1") == "done", timeout=2 * WAIT, what="WEB1 done on the page")
    assert fleet.monitor.last_event["WEB1"].event == "done"
    log = browser.find_element("id", "log").text
    assert "WEB1 accepted" in log


def test_the_pause_and_e_stop_buttons_stop_the_robots(browser, console):
    fleet = console[0]
    mon = fleet.monitor
    click(browser, "#pause-fleet-btn")
    until(lambda: all(p[3] == "1" for p in robots_on_page(browser).values()), what="every robot paused on the page")
    submit_from_page(browser, "WEB2", "chute_1", "B02-02")
    until(lambda: job_state(browser, "WEB2") == "accepted", what="WEB2 accepted")
    t0 = mon.now()
    until(lambda: mon.now() > t0 + 3.0, what="3 s of simulated time")
    assert [e.event for e in mon.events_of("WEB2")] == ["accepted"], "a paused fleet takes no job"
    click(browser, "#resume-fleet-btn")
    until(lambda: any(st.mode == "driving" for st in mon.status.values()), what="a robot driving WEB2")
    click(browser, "#estop-btn")
    until(lambda: all(mon.status[m.id].estop for m in MEMBERS), what="every agent reports the e-stop")
    until(lambda: all(st.mode != "driving" for st in mon.status.values()), what="every robot stopped")
    until(lambda: browser.find_element("id", "estop-btn").text == "RELEASE E-STOP", what="the button shows it")
    frozen = {m.id: (mon.status[m.id].x, mon.status[m.id].y) for m in MEMBERS}
    t0 = mon.now()
    until(lambda: mon.now() > t0 + 2.0, what="2 s of simulated time")
    for rid, pos in frozen.items():
        assert math.dist((mon.status[rid].x, mon.status[rid].y), pos) < 1e-6, f"{rid} moved during the e-stop"
    click(browser, "#estop-btn")
    until(lambda: not any(mon.status[m.id].estop for m in MEMBERS), what="the e-stop released")
    until(lambda: job_state(browser, "WEB2") == "done", timeout=2 * WAIT, what="WEB2 done after the release")


def test_bad_requests_on_the_websocket_are_answered_naming_the_field(console):
    import aiohttp

    url = console[2].replace("http://", "ws://") + "ws"
    requests = [('{"ref": 1, "type": "launch"}', "type: must be one of"),
                ('{"ref": 2, "type": "drive", "robot_id": "r1", "linear": NaN, "angular": 0}',
                 "linear: must be a finite number"),
                ('{"ref": 3, "type": "command", "command": {"command": "cancel"}}',
                 "command.task_id: required for 'cancel'"),
                ('{"ref": 4, "type": "submit", "task": {"pick": "chute_1", "place": "B01-01", "payload_kg": -1}}',
                 "task.payload_kg: must be >= 0"),
                ('{"ref": 5, "type": "command", "command": {"command": "send", "robot_id": "r9", "station": "x"}}',
                 "robot_id: unknown robot 'r9'"),
                ('{"ref": 6, "type": "manual", "robot_id": "no such robot!", "on": true}', "robot_id:"),
                ("not json", "request: not valid JSON")]

    async def talk():
        async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
            for text, _ in requests:
                await ws.send_str(text)
            replies = {}
            async with asyncio.timeout(WAIT):
                while len(replies) < len(requests):
                    msg = json.loads((await ws.receive()).data)
                    if msg["type"] == "reply":
                        replies[msg["ref"] if msg["ref"] is not None else 7] = msg
            return replies

    replies = asyncio.run(talk())
    for ref, (_, words) in enumerate(requests, start=1):
        assert not replies[ref]["ok"] and words in replies[ref]["message"], (ref, replies[ref])


def test_the_job_and_robot_buttons_cancel_reprioritise_send_and_drive_by_hand(browser, console):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.support.ui import Select

    fleet, node, _ = console
    mon = fleet.monitor
    log = lambda: browser.find_element("id", "log").text  # noqa: E731
    click(browser, "#pause-fleet-btn")
    submit_from_page(browser, "WEB3", "chute_2", "B04-01")
    until(lambda: job_state(browser, "WEB3") == "accepted", what="WEB3 accepted")
    row = browser.find_element("id", "job-WEB3")
    prio = row.find_element("css selector", "input.prio")
    prio.clear()
    prio.send_keys("7")
    row.find_element("css selector", "button.set-prio").click()
    until(lambda: "job WEB3: priority 0 -> 7" in log(), what="the priority reply")
    row.find_element("css selector", "button.cancel").click()
    until(lambda: job_state(browser, "WEB3") == "cancelled", what="WEB3 cancelled on the page")
    click(browser, "#resume-fleet-btn")
    # send a free robot to a parking spot from its row
    rid = until(lambda: next((m.id for m in MEMBERS if fleet.planner.fleet.robots[m.id].free), None),
                what="a free robot")
    robot_row = browser.find_element("id", f"row-{rid}")
    Select(robot_row.find_element("css selector", "select.station")).select_by_value("parking_2")
    robot_row.find_element("css selector", "button.send").click()
    spot = fleet.planner.fleet.parking["parking_2"]
    until(lambda: math.dist((mon.status[rid].x, mon.status[rid].y), spot) < 0.05, what=f"{rid} at parking_2")
    # manual drive with the drive pad
    robot_row.find_element("css selector", "button.manual-on").click()
    until(lambda: mon.status[rid].manual, what=f"{rid} in manual drive")
    Select(browser.find_element("id", "drive-robot")).select_by_value(rid)

    def hold(button, condition, seconds):
        """Hold a drive pad button until ``condition()`` or ``seconds`` wall seconds; whether it held.
        A press the page loses now and then (about 1 in 5 runs under load, cause not found yet:
        see the issue 12 note) is pressed again, at most three times within ``seconds``."""
        pad = browser.find_element("id", button)
        end = time.monotonic() + seconds
        for _ in range(3):
            ActionChains(browser).click_and_hold(pad).perform()
            try:
                press_end = min(end, time.monotonic() + seconds / 3)
                until(lambda t=press_end: condition() or time.monotonic() > t, timeout=seconds + 5.0, what=button)
            finally:
                ActionChains(browser).release(pad).perform()
            if condition():
                return True
        return condition()

    yaw0 = mon.status[rid].yaw
    assert hold("drive-left", lambda: abs(math.remainder(mon.status[rid].yaw - yaw0, math.tau)) > 0.3, WAIT), \
        f"{rid} turned by hand"
    start = (mon.status[rid].x, mon.status[rid].y)
    moved = lambda: math.dist((mon.status[rid].x, mon.status[rid].y), start) > 0.2  # noqa: E731
    # forwards, or backwards if something is in front of it
    assert hold("drive-fwd", moved, 10.0) or hold("drive-back", moved, 10.0), f"{rid} driven by hand"
    robot_row.find_element("css selector", "button.manual-off").click()
    until(lambda: not mon.status[rid].manual and not fleet.planner.fleet.robots[rid].manual,
          what=f"{rid} back in the plan")
    assert "manual " + rid + " on: robot " + rid + ": manual drive on" in log()


def test_an_obstacle_of_the_intelligent_space_is_drawn_and_cleared(browser, console):
    from std_msgs.msg import String

    from fleet_planner.ros.console.node import OBSTACLES_QOS, OBSTACLES_TOPIC

    fleet = console[0]
    pub = fleet.monitor.create_publisher(String, OBSTACLES_TOPIC, OBSTACLES_QOS)
    record = {"schema": "fleet/obstacle@1", "id": "pallet_1", "kind": "pallet", "x": 12.0, "y": 6.0,
              "radius": 0.4, "stamp": fleet.monitor.now(), "persistent": True}
    until(lambda: pub.get_subscription_count() > 0, what="the console hears obstacles")
    pub.publish(String(data=json.dumps(record)))
    until(lambda: browser.execute_script("return !!document.getElementById('obstacle-pallet_1')"),
          what="the obstacle on the map")
    pub.publish(String(data=json.dumps({**record, "cleared": True})))
    until(lambda: browser.execute_script("return !document.getElementById('obstacle-pallet_1')"),
          what="the obstacle gone")
