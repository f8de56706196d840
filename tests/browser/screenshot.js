// Open a page in headless Chromium (playwright-core), wait, take a screenshot: the browser half of
// tests/test_rerun_web.py. Usage: node screenshot.js URL OUT.png WAIT_MS CHROMIUM
// Software WebGL (SwiftShader): CI machines have no GPU.
const { chromium } = require('playwright-core');
(async () => {
  const [url, out, wait, executable] = process.argv.slice(2);
  const browser = await chromium.launch({
    executablePath: executable, headless: true,
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'],
  });
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  await page.goto(url, { waitUntil: 'load', timeout: 60000 });
  await page.waitForTimeout(parseInt(wait, 10));
  await page.screenshot({ path: out });
  console.log(JSON.stringify({ title: await page.title() }));
  await browser.close();
})().catch((e) => { console.error(String(e)); process.exit(1); });
