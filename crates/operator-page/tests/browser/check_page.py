"""Drives the operator page in a real headless Chromium (Debian's chromium and chromium-driver,
scripts/browser-env.sh) through Selenium: no console errors, the WebGL twin drawn (not a blank
canvas), Get adds a `data-inspection-id` element, Align puts the rms in mm in #result, and at a
tablet's 800 px width nothing scrolls sideways and the buttons are finger-sized.

    python check_page.py URL SCREENSHOT.png EXPECTED_INSPECTIONS

Prints one JSON line with what it saw; exits non-zero with the reason otherwise.
"""

import json
import sys
import tempfile

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

# Without the background-networking flags Chromium's own connections are refused on the CI
# machines and it logs errors; SwiftShader gives WebGL without a GPU.
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-dev-shm-usage",
    "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader",
    "--window-size=1280,900",
]

# Distinct colours in the twin's canvas, read back through a 2D canvas (the WebGL canvas keeps
# its drawing buffer): a blank or failed canvas has one or two.
COUNT_COLOURS = """
const twin = document.getElementById('twin');
const copy = document.createElement('canvas');
copy.width = twin.width; copy.height = twin.height;
const context = copy.getContext('2d');
context.drawImage(twin, 0, 0);
const pixels = context.getImageData(0, 0, copy.width, copy.height).data;
const colours = new Set();
for (let i = 0; i < pixels.length; i += 4 * 7) colours.add((pixels[i] << 16) | (pixels[i + 1] << 8) | pixels[i + 2]);
return colours.size;
"""


def button(driver, label):
    return driver.find_element(By.XPATH, f"//button[normalize-space()='{label}']")


def inspection_ids(driver):
    # Read in one script: the list is rebuilt on every state event, so element handles go stale.
    return driver.execute_script(
        "return [...document.querySelectorAll('[data-inspection-id]')].map((e) => e.dataset.inspectionId);"
    )


def main():
    url, screenshot, expected = sys.argv[1], sys.argv[2], int(sys.argv[3])
    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for flag in FLAGS:
        options.add_argument(flag)
    profile = tempfile.mkdtemp(prefix="operator-page-chromium-")
    options.add_argument(f"--user-data-dir={profile}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    try:
        wait = WebDriverWait(driver, 30)
        driver.get(url)
        labels = [b.text for b in driver.find_elements(By.CSS_SELECTOR, "button[data-command]")]
        wait.until(lambda d: len(inspection_ids(d)) >= expected)
        before = inspection_ids(driver)
        button(driver, "Get").click()
        wait.until(lambda d: len(inspection_ids(d)) == len(before) + 1)
        added = [i for i in inspection_ids(driver) if i not in before]
        button(driver, "Align").click()
        wait.until(lambda d: "rms" in d.find_element(By.ID, "result").text)
        result = driver.find_element(By.ID, "result").text
        if " mm" not in result:
            raise SystemExit(f"#result has no mm: {result!r}")
        # The live robot and the aligned part are drawn once their events arrived.
        wait.until(lambda d: d.execute_script(COUNT_COLOURS) > 20)
        colours = driver.execute_script(COUNT_COLOURS)
        driver.save_screenshot(screenshot)
        # A tablet held upright: no sideways scrolling, buttons big enough for a finger.
        driver.set_window_size(800, 1280)
        wait.until(lambda d: d.execute_script("return window.innerWidth") <= 800)
        overflow = driver.execute_script("return document.documentElement.scrollWidth - window.innerWidth")
        if overflow > 0:
            raise SystemExit(f"the page scrolls sideways by {overflow} px at 800 px wide")
        smallest = driver.execute_script(
            "return Math.min(...[...document.querySelectorAll('button[data-command]')].map((b) => b.getBoundingClientRect().height));"
        )
        if smallest < 44:
            raise SystemExit(f"a command button is {smallest} px high: too small to touch")
        errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        if errors:
            raise SystemExit(f"console errors: {errors}")
        print(json.dumps({"labels": labels, "added": added, "result": result, "colours": colours}))
    finally:
        driver.quit()


if __name__ == "__main__":
    main()
