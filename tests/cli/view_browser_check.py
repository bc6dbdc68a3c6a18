#!/usr/bin/env python3
"""The page of `duplex view` in a real browser: headless Chromium driven by Selenium (Debian's
chromium, chromium-driver and python3-selenium; scripts/test installs them).

Loads the page, waits for the first frame in #view, hovers and clicks the pixel where the box is
(found from the interface's "ids" render of the same camera) and reads the picked path from #pick,
drags the part (the server's scene then has the box moved, the frame changed, #stats shows an update
time), undoes with the U key (the box back where it was). Screenshots are kept in
WORK_DIR/screenshots as the test's artefacts.

Exits 77 (CTest: skipped) with a message when Chromium, its driver or Selenium is missing.

Usage: view_browser_check.py DUPLEX_CLI WORK_DIR
       view_browser_check.py DUPLEX_CLI WORK_DIR --screenshot SCENE OUT.png   (a picture of SCENE's page)
"""

import math
import os
import re
import shutil
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from view_support import Server, expect, wait_for, write_scene  # noqa: E402

CHROMIUM, DRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"


def browser():
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        print("view_browser_check: SKIPPED: python3-selenium is not installed (scripts/test installs it)")
        sys.exit(77)
    for path in (CHROMIUM, DRIVER):
        if not os.path.exists(path):
            print(f"view_browser_check: SKIPPED: {path} is missing (Debian chromium and chromium-driver; "
                  "scripts/test installs them)")
            sys.exit(77)
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1280,900",
                "--disable-dev-shm-usage"):
        options.add_argument(arg)
    return webdriver.Chrome(service=Service(DRIVER), options=options)


def box_translation(server):
    node = next(n for n in server.json("GET", "/api/scene")["nodes"] if n["path"] == "/parts/box")
    return [node["local"][3], node["local"][7], node["local"][11]]


def box_local(server):
    """/parts/box's local transform (row-major 3x4)."""
    return next(n["local"] for n in server.json("GET", "/api/scene")["nodes"] if n["path"] == "/parts/box")


def view_pixel(driver, x, y):
    """The RGB of pixel (x, y) of the image the page shows in #view (read back through a canvas)."""
    return driver.execute_script(
        "const img = document.getElementById('view'), c = document.createElement('canvas');"
        "c.width = img.naturalWidth; c.height = img.naturalHeight;"
        "const g = c.getContext('2d'); g.drawImage(img, 0, 0);"
        "return Array.from(g.getImageData(arguments[0], arguments[1], 1, 1).data).slice(0, 3);", x, y)


def edge_pixel(server, camera):
    """A pixel that the server's feature edges darken most (among those with edge pixels around)."""
    from demo_check import decode_png
    w, h = camera["width"], camera["height"]
    plain, lined = [b"".join(decode_png(server.request("POST", "/api/render", {"camera": camera, "format": "png",
                                                                            "edges": e})[2])[2])
                    for e in (False, True)]
    dark = [sum(plain[3 * i:3 * i + 3]) - sum(lined[3 * i:3 * i + 3]) > 60 for i in range(w * h)]
    best = max(((sum(dark[(y + dy) * w + x + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)), x, y)
                for y in range(1, h - 1) for x in range(1, w - 1) if dark[y * w + x]))
    return best[1], best[2]


def frames(driver):
    return int(driver.find_element("id", "view").get_attribute("data-frames") or 0)


def screenshot_only(cli, work, scene, out):
    server = Server(cli, scene)
    driver = browser()
    try:
        from selenium.webdriver.common.action_chains import ActionChains
        scene = server.json("GET", "/api/scene")
        camera = dict(scene["camera"], width=640, height=400)
        ids, _ = server.ids(camera)
        counts = {}
        for inst, _prim in ids:
            counts[inst] = counts.get(inst, 0) + 1
        floor = max((c, i) for i, c in counts.items() if i != 0xFFFFFFFF)[1]
        # A part to select: the pixel nearest the frame's centre that shows neither sky nor floor.
        part = min((i for i, v in enumerate(ids) if v[0] not in (floor, 0xFFFFFFFF)),
                   key=lambda i: (i % 640 - 320) ** 2 + (i // 640 - 200) ** 2)
        driver.get(server.ready["url"])
        wait_for(lambda: frames(driver) >= 1, 60, "the first frame")
        box_el = driver.find_element("id", "frame-box")
        ActionChains(driver).move_to_element_with_offset(box_el, part % 640 - 320, part // 640 - 200).click().perform()
        wait_for(lambda: driver.find_element("id", "pick").text != "(none)", 20, "a selection")
        ActionChains(driver).move_by_offset(1, 0).perform()
        time.sleep(1.5)  # the full-resolution frame, the hover pick and the plot
        driver.save_screenshot(out)
        print(f"view_browser_check: wrote {out}")
    finally:
        driver.quit()
        server.stop()


def main():
    cli, work = sys.argv[1], sys.argv[2]
    if "--screenshot" in sys.argv:
        i = sys.argv.index("--screenshot")
        return screenshot_only(cli, work, sys.argv[i + 1], sys.argv[i + 2])
    from selenium.webdriver.common.action_chains import ActionChains
    shots = os.path.join(work, "screenshots")
    shutil.rmtree(shots, ignore_errors=True)
    os.makedirs(shots)
    server = Server(cli, write_scene(work, name="view_browser_scene.json"))
    driver = browser()
    try:
        scene = server.json("GET", "/api/scene")
        camera = dict(scene["camera"], width=640, height=400)
        ids, _ = server.ids(camera)
        box = [i for i, v in enumerate(ids) if v[0] == 1]
        expect(box, "the box is in the frame")
        mx = sum(i % 640 for i in box) / len(box)
        my = sum(i // 640 for i in box) / len(box)
        bi = min(box, key=lambda i: (i % 640 - mx) ** 2 + (i // 640 - my) ** 2)
        bx, by = bi % 640, bi // 640

        driver.get(server.ready["url"])
        wait_for(lambda: frames(driver) >= 1, 60, "the first frame in #view")
        view = driver.find_element("id", "view")
        expect(view.get_attribute("naturalWidth") in ("640", "213"), "a frame of the page's size")
        driver.save_screenshot(os.path.join(shots, "1_loaded.png"))

        box_el = driver.find_element("id", "frame-box")
        # Selenium 4 offsets are from the element's centre.
        ActionChains(driver).move_to_element_with_offset(box_el, bx - 320, by - 200).perform()
        wait_for(lambda: "/parts/box" in driver.find_element("id", "hover").text, 20, "the hover pick of the box")
        n = frames(driver)  # before the click: the frame with the selection may be quick
        ActionChains(driver).click().perform()
        wait_for(lambda: driver.find_element("id", "pick").text == "/parts/box", 20, "#pick to show /parts/box")
        wait_for(lambda: frames(driver) > n, 20, "the frame with the selection")
        time.sleep(0.3)
        before_png = view.screenshot_as_png
        before = box_translation(server)
        driver.save_screenshot(os.path.join(shots, "2_selected.png"))

        # Drag the selected part 60 px down in steps, then release.
        ActionChains(driver).move_to_element_with_offset(box_el, bx - 320, by - 200).perform()
        wait_for(lambda: "/parts/box" in driver.find_element("id", "hover").text, 20, "hover before the drag")
        chain = ActionChains(driver).click_and_hold()
        for _ in range(6):
            chain = chain.move_by_offset(0, 10).pause(0.05)
        chain.release().perform()
        wait_for(lambda: box_translation(server) != before, 20, "the drag's edit to reach the scene")
        after = box_translation(server)
        expect(abs(after[0] - before[0]) + abs(after[1] - before[1]) + abs(after[2] - before[2]) > 0.05,
               f"the box moved: {before} -> {after}")
        wait_for(lambda: re.search(r"update\s+[0-9.]+ ms", driver.find_element("id", "stats").text), 20,
                 "#stats to show an update time")
        time.sleep(0.8)  # the full-resolution frame after the drag
        after_png = view.screenshot_as_png
        expect(after_png != before_png, "the frame changed after the drag")
        driver.save_screenshot(os.path.join(shots, "3_dragged.png"))

        # Undo (key U): the whole drag goes back as one.
        driver.find_element("tag name", "body").send_keys("u")
        wait_for(lambda: box_translation(server) == before, 20, "undo to restore the box")
        driver.save_screenshot(os.path.join(shots, "4_undone.png"))

        # Ctrl-drag turns the selected part (a turntable about the image's up through the grabbed
        # point, half a degree per pixel): 60 px right give a rotation of about 30 degrees, and
        # undo takes it back.
        from selenium.webdriver.common.keys import Keys
        ActionChains(driver).move_to_element_with_offset(box_el, bx - 320, by - 200).perform()
        wait_for(lambda: "/parts/box" in driver.find_element("id", "hover").text, 20, "hover before the turn")
        chain = ActionChains(driver).key_down(Keys.CONTROL).click_and_hold()
        for _ in range(6):
            chain = chain.move_by_offset(10, 0).pause(0.05)
        chain.release().key_up(Keys.CONTROL).perform()
        wait_for(lambda: box_local(server)[0] != 1.0, 20, "the turn's edit to reach the scene")
        time.sleep(0.5)  # the last step of the turn
        m = box_local(server)
        rows = [m[0:3], m[4:7], m[8:11]]
        for i in range(3):
            for j in range(3):
                d = sum(rows[i][k] * rows[j][k] for k in range(3))
                expect(abs(d - (i == j)) < 1e-6, f"the turned box's linear part is a rotation: {rows}")
        angle = math.degrees(math.acos(max(-1.0, min(1.0, (rows[0][0] + rows[1][1] + rows[2][2] - 1) / 2))))
        expect(20 < angle < 35, f"the box turned by {angle:.1f} degrees for a 60 px Ctrl-drag")
        driver.save_screenshot(os.path.join(shots, "5_turned.png"))
        driver.find_element("tag name", "body").send_keys("u")
        wait_for(lambda: box_local(server)[0] == 1.0 and box_translation(server) == before, 20,
                 "undo to take the turn back")

        # Feature edges: the page draws them (checkbox #edges, on by default); off, the frame
        # there is lighter. Read at a pixel the server's edges darken most.
        ex, ey = edge_pixel(server, camera)
        ActionChains(driver).move_to_element_with_offset(box_el, 300, 190).perform()  # away from the parts
        time.sleep(0.8)
        wait_for(lambda: driver.find_element("id", "view").get_attribute("naturalWidth") == "640", 20,
                 "a full-resolution frame")
        with_edges = view_pixel(driver, ex, ey)
        n = frames(driver)
        driver.find_element("id", "edges").click()
        wait_for(lambda: frames(driver) > n, 20, "the frame without edges")
        time.sleep(0.3)
        without = view_pixel(driver, ex, ey)
        driver.save_screenshot(os.path.join(shots, "6_no_edges.png"))
        expect(sum(without) - sum(with_edges) > 60,
               f"pixel ({ex}, {ey}): with edges {with_edges}, without {without}: the edges are not drawn")
        logs = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
        expect(not logs, f"browser console errors: {logs[:3]}")
        print(f"view_browser_check: all checks passed; screenshots in {shots}")
    finally:
        driver.quit()
        server.stop()


if __name__ == "__main__":
    main()
