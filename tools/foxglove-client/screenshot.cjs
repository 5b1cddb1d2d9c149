#!/usr/bin/env node
// Opens a page in Debian's headless Chromium (puppeteer-core, pointed at the system browser:
// nothing is downloaded) and saves a screenshot once the page has drawn, offline.
//
//   node screenshot.cjs --url http://127.0.0.1:9090/?url=... --out shot.png
//                       [--wait-s 30] [--width 1280] [--height 800] [--chromium /usr/bin/chromium]
//
// It waits `--wait-s` seconds after the page loaded (Rerun's web viewer loads its wasm and
// then the recording; the software rasterizer is slow), then writes the PNG. Exit status 0
// when the PNG was written, 1 otherwise (one line on stderr says why); the page's console
// errors are printed on stderr.
"use strict";

const puppeteer = require("puppeteer-core");
const fs = require("fs");
const os = require("os");
const path = require("path");

function parseArgs(argv) {
  const out = { url: null, out: null, waitS: 30, width: 1280, height: 800, chromium: "/usr/bin/chromium" };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    const next = () => {
      if (i + 1 >= argv.length) {
        console.error(`screenshot: ${a} needs a value`);
        process.exit(2);
      }
      return argv[++i];
    };
    if (a === "--url") out.url = next();
    else if (a === "--out") out.out = next();
    else if (a === "--wait-s") out.waitS = Number(next());
    else if (a === "--width") out.width = Number(next());
    else if (a === "--height") out.height = Number(next());
    else if (a === "--chromium") out.chromium = next();
    else {
      console.error(`screenshot: unknown argument ${a}`);
      process.exit(2);
    }
  }
  if (!out.url || !out.out) {
    console.error("screenshot: --url and --out are required");
    process.exit(2);
  }
  return out;
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  if (!fs.existsSync(args.chromium)) {
    console.error(`screenshot: no ${args.chromium}: run tools/setup.sh (apt-get install chromium)`);
    process.exit(1);
  }
  const profile = fs.mkdtempSync(path.join(os.tmpdir(), "agp-chromium-"));
  let browser;
  try {
    browser = await puppeteer.launch({
      executablePath: args.chromium,
      headless: true,
      userDataDir: profile,
      args: [
        "--no-sandbox",
        "--disable-gpu",
        "--use-angle=swiftshader",
        "--enable-unsafe-swiftshader",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        `--window-size=${args.width},${args.height}`,
      ],
      defaultViewport: { width: args.width, height: args.height },
      protocolTimeout: 180000,
    });
    const page = await browser.newPage();
    page.on("console", (m) => {
      if (m.type() === "error") console.error(`page console: ${m.text()}`);
    });
    page.on("pageerror", (e) => console.error(`page error: ${e.message}`));
    await page.goto(args.url, { waitUntil: "load", timeout: 120000 });
    await new Promise((r) => setTimeout(r, args.waitS * 1000));
    await page.screenshot({ path: args.out, type: "png" });
    console.log(`screenshot: ${args.out}`);
  } finally {
    if (browser) await browser.close();
    fs.rmSync(profile, { recursive: true, force: true });
  }
}

main().catch((e) => {
  console.error(`screenshot: ${e && e.message ? e.message : e}`);
  process.exit(1);
});
