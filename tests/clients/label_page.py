"""Drives `travmap label`'s page in headless Chromium as a person would: answers the
first asked cell by clicking "Traversable", the next by the key N, skips the third by
the key S, paints one cell that was not asked (P, then a click on the grid), reloads
the page, and reads back what the page then shows. Prints one JSON line: the answers
before and after the reload, every URL the page requested, the page's console errors.

Usage:
    label_page.py URL SCREENSHOT.png [--chromium PATH] [--timeout 90]

Only the standard library (and viewer_screenshot.py's DevTools client beside it).
"""

import argparse
import base64
import json
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from viewer_screenshot import Browser, Failure, find_chromium  # noqa: E402


class RecordingBrowser(Browser):
    """A Browser that keeps the URL of every request the page makes."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.requests = []

    def _event(self, m):
        if m.get("method") == "Network.requestWillBeSent":
            self.requests.append(m["params"]["request"]["url"])
        super()._event(m)


ANSWERS_JS = "JSON.stringify([...state.answers].sort())"
PROGRESS_JS = "document.getElementById('progress').textContent"


def wait_for(browser, expression, deadline, what):
    while time.monotonic() < deadline:
        value = browser.evaluate(expression, deadline)
        if value:
            return value
        time.sleep(0.1)
    raise Failure(f"timed out waiting for {what}; console: {browser.console[-5:]}")


def answers(browser, deadline):
    return json.loads(browser.evaluate(ANSWERS_JS, deadline) or "[]")


def wait_for_answers(browser, count, deadline):
    wait_for(browser, f"state.answers.size === {count}", deadline, f"{count} answers")


def click(browser, x, y, deadline):
    for kind in ("mousePressed", "mouseReleased"):
        browser.call("Input.dispatchMouseEvent",
                     {"type": kind, "x": x, "y": y, "button": "left", "clickCount": 1}, deadline)


def click_element(browser, element_id, deadline):
    box = json.loads(browser.evaluate(
        f"JSON.stringify(document.getElementById('{element_id}').getBoundingClientRect())",
        deadline))
    click(browser, box["x"] + box["width"] / 2, box["y"] + box["height"] / 2, deadline)


def press(browser, key, deadline):
    code = {"n": ("KeyN", 78), "s": ("KeyS", 83), "p": ("KeyP", 80), "t": ("KeyT", 84)}[key]
    for kind in ("keyDown", "keyUp"):
        params = {"type": kind, "key": key, "code": code[0], "windowsVirtualKeyCode": code[1]}
        if kind == "keyDown":
            params["text"] = key
        browser.call("Input.dispatchKeyEvent", params, deadline)


# Where on screen a predictable cell of the current frame lies that was neither asked
# nor answered: the page's own state says which cells hold features.
UNASKED_CELL_JS = r"""(async () => {
  const { view } = await frame(state.current.frame);
  const side = view.cells_per_side;
  const canvas = document.getElementById('grid');
  const box = canvas.getBoundingClientRect();
  for (let cell = 0; cell < side * side; cell++) {
    if (view.calls[cell] === '.' || state.askedIndex.has(key(state.current.frame, cell))) continue;
    if (state.answers.has(key(state.current.frame, cell))) continue;
    const col = cell % side, rowFromTop = side - 1 - Math.floor(cell / side);
    const scale = box.width / canvas.width;
    return JSON.stringify({
      cell,
      x: box.left + (col + 0.5) * view.pixels_per_cell * scale,
      y: box.top + (rowFromTop + 0.5) * view.pixels_per_cell * scale,
    });
  }
  return null;
})()"""


def run(opts, work):
    deadline = time.monotonic() + opts.timeout
    browser = RecordingBrowser(find_chromium(opts.chromium), work, 1400, 1000, [], False)
    try:
        browser.open_page("about:blank", 1400, 1000, deadline)
        browser.call("Network.enable", deadline=deadline)
        browser.call("Page.navigate", {"url": opts.url}, deadline)
        wait_for(browser, "document.getElementById('asking').textContent.startsWith('asked cell')",
                 deadline, "the first question")
        click_element(browser, "traversable", deadline)
        wait_for_answers(browser, 1, deadline)
        press(browser, "n", deadline)
        wait_for_answers(browser, 2, deadline)
        press(browser, "s", deadline)
        wait_for_answers(browser, 3, deadline)
        press(browser, "p", deadline)
        r = browser.call("Runtime.evaluate", {"expression": UNASKED_CELL_JS, "awaitPromise": True,
                                              "returnByValue": True}, deadline)
        target = json.loads(r["result"]["value"])
        click(browser, target["x"], target["y"], deadline)
        wait_for_answers(browser, 4, deadline)
        before = answers(browser, deadline)
        progress_before = browser.evaluate(PROGRESS_JS, deadline)
        browser.call("Page.reload", {}, deadline)
        wait_for(browser, "typeof state !== 'undefined' && state.answers.size === 4",
                 deadline, "the answers after a reload")
        after = answers(browser, deadline)
        time.sleep(0.5)
        png = base64.b64decode(browser.call("Page.captureScreenshot", {"format": "png"},
                                            deadline)["data"])
        with open(opts.screenshot, "wb") as f:
            f.write(png)
        return {
            "ok": before == after,
            "answers": before,
            "after_reload": after,
            "painted_cell": target["cell"],
            "progress": progress_before,
            "requests": browser.requests,
            "console": browser.console,
        }
    finally:
        browser.close()


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("url")
    parser.add_argument("screenshot")
    parser.add_argument("--chromium")
    parser.add_argument("--timeout", type=float, default=90)
    opts = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="travmap-label-page-") as work:
        try:
            result = run(opts, work)
        except Failure as error:
            result = {"ok": False, "error": str(error)}
    print(json.dumps(result))
    sys.exit(0 if result.get("ok") else 1)


if __name__ == "__main__":
    main()
