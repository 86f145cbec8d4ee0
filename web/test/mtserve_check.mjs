// node test/mtserve_check.mjs BIN_DIR: mtserve's HTTP behaviour (CTest Web.Mtserve): 206 with
// Content-Range for A-B, A- and -N ranges, 416 beyond the end, HEAD without a body, content types,
// 403 for paths that climb out of DIR (plain and percent-encoded), 404, 405, and --no-ranges' 200.
import fs from 'node:fs';
import path from 'node:path';
import os from 'node:os';
import net from 'node:net';
import { spawn } from 'node:child_process';

const bin = process.argv[2];
const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'mtserve-'));
const data = Buffer.from(Array.from({ length: 1000 }, (_, i) => i % 251));
fs.mkdirSync(path.join(dir, 'sub'));
fs.writeFileSync(path.join(dir, 'sub', 'f.mt'), data);
fs.writeFileSync(path.join(dir, 'a.wasm'), 'x');
fs.writeFileSync(path.join(os.tmpdir(), 'mtserve-outside.txt'), 'secret');
const serve = (extra) => new Promise((resolve, reject) => {
  const p = spawn(path.join(bin, 'mtserve'), [dir, '--port', '0', '-q', ...extra], { stdio: ['ignore', 'pipe', 'inherit'] });
  p.stdout.on('data', (d) => { const m = /:(\d+)\//.exec(String(d)); if (m) resolve({ p, port: Number(m[1]) }); });
  p.on('exit', (c) => reject(new Error(`mtserve exited ${c}`)));
});
// A raw request (fetch would normalize "/../"), the whole answer as text.
const raw = (port, line, headers = '') => new Promise((resolve) => {
  const s = net.connect(port, '127.0.0.1', () => s.write(`${line}\r\nHost: x\r\nConnection: close\r\n${headers}\r\n`));
  const chunks = [];
  s.on('data', (c) => chunks.push(c));
  s.on('end', () => resolve(Buffer.concat(chunks)));
});
let failed = 0, passed = 0;
const check = (cond, msg) => { if (cond) ++passed; else { ++failed; console.log(`FAIL ${msg}`); } };
const a = await serve([]);
const b = await serve(['--no-ranges']);
const base = `http://127.0.0.1:${a.port}`;
let r = await fetch(`${base}/sub/f.mt`, { headers: { Range: 'bytes=10-19' } });
let body = Buffer.from(await r.arrayBuffer());
check(r.status === 206 && r.headers.get('content-range') === 'bytes 10-19/1000' && body.equals(data.subarray(10, 20)), 'range A-B');
r = await fetch(`${base}/sub/f.mt`, { headers: { Range: 'bytes=990-' } });
body = Buffer.from(await r.arrayBuffer());
check(r.status === 206 && body.equals(data.subarray(990)), 'range A-');
r = await fetch(`${base}/sub/f.mt`, { headers: { Range: 'bytes=-32' } });
body = Buffer.from(await r.arrayBuffer());
check(r.status === 206 && r.headers.get('content-range') === 'bytes 968-999/1000' && body.equals(data.subarray(968)), 'suffix range');
r = await fetch(`${base}/sub/f.mt`, { headers: { Range: 'bytes=1000-' } });
check(r.status === 416 && r.headers.get('content-range') === 'bytes */1000', '416 beyond the end');
r = await fetch(`${base}/sub/f.mt`);
body = Buffer.from(await r.arrayBuffer());
check(r.status === 200 && body.equals(data) && r.headers.get('accept-ranges') === 'bytes', 'whole file');
r = await fetch(`${base}/sub/f.mt`, { method: 'HEAD' });
check(r.status === 200 && r.headers.get('content-length') === '1000', 'HEAD');
r = await fetch(`${base}/a.wasm`);
check(r.headers.get('content-type') === 'application/wasm', 'wasm content type');
r = await fetch(`${base}/nothing`);
check(r.status === 404, '404');
r = await fetch(`${base}/sub/f.mt`, { method: 'POST', body: 'x' });
check(r.status === 405, '405');
for (const t of ['/../mtserve-outside.txt', '/sub/../../mtserve-outside.txt', '/%2e%2e/mtserve-outside.txt', '/sub/%2E%2E/%2e%2e/mtserve-outside.txt']) {
  const ans = String(await raw(a.port, `GET ${t} HTTP/1.1`));
  check(/^HTTP\/1.1 403/.test(ans) && !ans.includes('secret'), `403 for ${t}`);
}
r = await fetch(`http://127.0.0.1:${b.port}/sub/f.mt`, { headers: { Range: 'bytes=10-19' } });
body = Buffer.from(await r.arrayBuffer());
check(r.status === 200 && body.length === 1000 && !r.headers.get('accept-ranges'), '--no-ranges answers 200');
a.p.kill();
b.p.kill();
fs.rmSync(dir, { recursive: true, force: true });
fs.rmSync(path.join(os.tmpdir(), 'mtserve-outside.txt'));
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
