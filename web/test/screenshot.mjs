// node test/screenshot.mjs BIN_DIR FILE.mt OUT.png [QUERY]: the viewer page on FILE.mt (served by
// mtserve) in headless Chromium at 1280x720, once the cut has converged (or after 60 s), with its HUD.
// The screenshots in docs/ are made with it (docs/web.md gives the commands).
import fs from 'node:fs';
import path from 'node:path';
import os from 'node:os';
import { spawn } from 'node:child_process';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const [bin, file, out, query = ''] = process.argv.slice(2);
const root = fs.mkdtempSync(path.join(os.tmpdir(), 'mtshot-'));
fs.symlinkSync(path.resolve(here, '..'), path.join(root, 'web'));
fs.symlinkSync(path.resolve(file), path.join(root, 'model.mt'));
const srv = await new Promise((resolve, reject) => {
  const p = spawn(path.join(bin, 'mtserve'), [root, '--port', '0', '-q'], { stdio: ['ignore', 'pipe', 'inherit'] });
  p.stdout.on('data', (d) => { const m = /:(\d+)\//.exec(String(d)); if (m) resolve({ p, port: m[1] }); });
  p.on('exit', (c) => reject(new Error(`mtserve exited ${c}`)));
});
const browser = await chromium.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update', '--disable-sync',
    '--no-first-run', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'] });
const page = await browser.newPage({ viewport: { width: 1280, height: 720 } });
await page.goto(`http://127.0.0.1:${srv.port}/web/viewer.html?file=/model.mt&${query}`);
await page.waitForFunction(() => {
  const v = window.mtViewer;
  if (v.error) return true;
  const f = v.frames;
  return f.length > 20 && f.slice(-10).every((x) => x.moves === 0 && x.pending === 0);
}, null, { timeout: 60000, polling: 200 }).catch(() => {});
await page.waitForTimeout(1500);  // the HUD refreshes every 10 frames
await page.screenshot({ path: out });
const f = await page.evaluate(() => window.mtViewer.frames.at(-1));
console.log(`${out}: ${f.triangles} triangles in the cut, screen error ${f.err.toFixed(2)} px, ${(f.bytesRead / 2 ** 20).toFixed(2)} MiB fetched`);
await browser.close();
srv.p.kill();
fs.rmSync(root, { recursive: true, force: true });
