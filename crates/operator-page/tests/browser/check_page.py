"""Drives the operator page in a real headless Chromium (Debian's chromium and chromium-driver,
scripts/browser-env.sh) through Selenium: no console errors, the WebGL twin drawn (not a blank
canvas), another client's get shows up without a reload, Get adds a `data-inspection-id`
element, Align puts the rms in mm and the pose uncertainty in #result, Diagnose draws the diagnosis charts, and at a
tablet's 800 px width nothing scrolls sideways and the buttons are finger-sized.

    python check_page.py URL SCREENSHOT.png EXPECTED_INSPECTIONS

Once the page shows EXPECTED_INSPECTIONS it prints `other-client` and reads one line from stdin:
the id of an inspection another client took meanwhile, which must then appear on the page.
At the end it prints one JSON line with what it saw; it exits non-zero with the reason otherwise.
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


# Pixels of the next suggested touch's violet (0x7c3aed, lit): blue well above red above green.
COUNT_VIOLET = """
const twin = document.getElementById('twin');
const copy = document.createElement('canvas');
copy.width = twin.width; copy.height = twin.height;
const context = copy.getContext('2d');
context.drawImage(twin, 0, 0);
const pixels = context.getImageData(0, 0, copy.width, copy.height).data;
let violet = 0;
for (let i = 0; i < pixels.length; i += 4) {
  const [r, g, b] = [pixels[i], pixels[i + 1], pixels[i + 2]];
  if (b > r + 40 && r > g + 40) violet += 1;
}
return violet;
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
        wait.until(lambda d: "bridge tcp://" in d.find_element(By.ID, "endpoints").text)
        endpoints = driver.find_element(By.ID, "endpoints").text
        wait.until(lambda d: len(inspection_ids(d)) >= expected)
        # Another client takes a touch while the page is open; no reload here.
        print("other-client", flush=True)
        other = sys.stdin.readline().strip()
        wait.until(lambda d: other in inspection_ids(d))
        before = inspection_ids(driver)
        button(driver, "Get").click()
        wait.until(lambda d: len(inspection_ids(d)) == len(before) + 1)
        added = [i for i in inspection_ids(driver) if i not in before]
        button(driver, "Align").click()
        wait.until(lambda d: "rms" in d.find_element(By.ID, "result").text)
        result = driver.find_element(By.ID, "result").text
        if " mm" not in result:
            raise SystemExit(f"#result has no mm: {result!r}")
        if "mm of the truth at 95% confidence; weakest: " not in result:
            raise SystemExit(f"#result has no pose uncertainty: {result!r}")
        # Diagnose: the verdict in #result, the charts and tables in the diagnosis panel.
        button(driver, "Diagnose").click()
        wait.until(lambda d: d.find_element(By.ID, "result").text.startswith("Diagnosis"))
        wait.until(lambda d: d.execute_script(
            "const p = document.getElementById('diagnosis-panel');"
            "return !p.hidden && p.open && p.querySelector('svg rect') !== null"
            " && p.querySelector('#alternatives') !== null;"
        ))
        diagnosis = driver.execute_script(
            "const p = document.getElementById('diagnosis-panel');"
            "return {summary: document.getElementById('diagnosis-summary').textContent,"
            " bars: p.querySelectorAll('svg rect[fill=\"#2a6fdb\"]').length,"
            " touches: p.querySelectorAll('#touches tr').length - 1,"
            " width: p.querySelector('svg').getBoundingClientRect().width,"
            " panel: p.getBoundingClientRect().width};"
        )
        if diagnosis["width"] > diagnosis["panel"] + 1:
            raise SystemExit(f"the diagnosis plot is wider than its panel: {diagnosis}")
        # The live robot and the aligned part are drawn once their events arrived.
        wait.until(lambda d: d.execute_script(COUNT_COLOURS) > 20)
        colours = driver.execute_script(COUNT_COLOURS)
        violet = driver.execute_script(COUNT_VIOLET)
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
        listed = inspection_ids(driver)
        print(json.dumps({"labels": labels, "endpoints": endpoints, "other": other, "added": added, "result": result,
                          "colours": colours, "violet": violet, "diagnosis": diagnosis, "listed": listed}))
    finally:
        driver.quit()


if __name__ == "__main__":
    main()
