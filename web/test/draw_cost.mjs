// One full draw of a converged cut, waited for (window.mtViewer.drawRate), in headless Chromium
// (SwiftShader) at 1280x720, for several ways of drawing the back faces: docs/web.md's "Back faces".
//   node test/draw_cost.mjs BIN_DIR FILE.mt [--view EX,EY,EZ,TX,TY,TZ] [--fixed TRIANGLES=2000]
//        [--variants front,,double,twopass=1] (viewer.html queries: side=front, default, side=double, ...)
// Prints per variant: back-pass patches / patches drawn, triangles, median and least of 15 draws (ms).
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { spawn } from 'node:child_process';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
const opt = (name, def) => { const i = args.indexOf(name); return i >= 0 ? args[i + 1] : def; };
const [binDir, file] = args;
const view = opt('--view', '0,-1.2,0.3,0,0,0'), fixed = Number(opt('--fixed', 2000));
const variants = opt('--variants', 'side=front,,side=double').split(',');
const root = fs.mkdtempSync(path.join(os.tmpdir(), 'mtdraw-'));
fs.symlinkSync(path.resolve(here, '..'), path.join(root, 'web'));
fs.symlinkSync(path.resolve(file), path.join(root, 'model.mt'));
const srv = await new Promise((resolve, reject) => {
  const p = spawn(path.join(binDir, 'mtserve'), [root, '--port', '0', '-q'], { stdio: ['ignore', 'pipe', 'inherit'] });
  p.stdout.on('data', (d) => { const m = /:(\d+)\//.exec(String(d)); if (m) resolve({ proc: p, base: `http://127.0.0.1:${m[1]}` }); });
  p.on('exit', (c) => reject(new Error(`mtserve exited ${c}`)));
});
const browser = await chromium.launch({ executablePath: '/usr/bin/chromium', headless: true,
  args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'] });
for (const v of variants) {
  const page = await browser.newPage({ viewport: { width: 1280, height: 720 } });
  await page.goto(`${srv.base}/web/viewer.html?file=/model.mt&plain&fixed=${fixed}&view=${view}${v ? '&' + v : ''}`);
  await page.waitForFunction(() => window.mtViewer && window.mtViewer.ready && window.mtViewer.frames.length > 20 &&
    window.mtViewer.frames.slice(-8).every((x) => x.moves === 0 && x.pending === 0), null, { timeout: 180000 });
  const r = await page.evaluate(() => ({ ...window.mtViewer.drawRate(15), f: window.mtViewer.frames.at(-1) }));
  const ms = r.ms.sort((a, b) => a - b);
  console.log(`${(v || 'default').padEnd(14)} back pass ${r.f.backPatches}/${r.f.patches} patches, ${r.triangles} triangles: median ${ms[7].toFixed(1)} ms, least ${ms[0].toFixed(1)} ms`);
  await page.close();
}
await browser.close();
srv.proc.kill();
fs.rmSync(root, { recursive: true, force: true });
