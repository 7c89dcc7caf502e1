"""What the page's browser tests share: Debian's Chromium driven by Playwright, the page's
script errors collected, and waiting for a condition in the page with a deadline (a failing
wait leaves a screenshot of what the page showed)."""


def open_page(playwright, url):
    """The page at `url` in a new headless Chromium: (browser, page, the page's errors)."""
    browser = playwright.chromium.launch(executable_path="/usr/bin/chromium", args=["--no-sandbox"])
    # Playwright evaluates its expressions with eval, which the page's policy forbids.
    context = browser.new_context(bypass_csp=True, viewport={"width": 1500, "height": 900})
    page = context.new_page()
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    return browser, page, errors


def wait(page, expression, what, screenshot, timeout=30.0):
    """Wait until `expression` (JavaScript) is true in the page; else stop, saying `what` was
    awaited, with a screenshot at `screenshot`."""
    try:
        page.wait_for_function(expression, timeout=timeout * 1000)
    except Exception as error:  # noqa: BLE001 — say what was awaited
        page.screenshot(path=screenshot)
        raise SystemExit(f"the page never showed {what}: {error}")
