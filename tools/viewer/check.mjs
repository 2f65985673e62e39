#!/usr/bin/env node
// Headless-Chromium checks of what fresco shows people (Debian's chromium, driven by
// playwright-core; no browser download). Prints one JSON line and exits 0 when the check
// passes, 1 when it fails, 2 on bad usage or when Chromium cannot start.
//
//   node check.mjs report <ws>/report.html <screenshot.png>
//     opens the report (served from its folder on 127.0.0.1), waits for its model viewer,
//     and checks: no console error, no page error, the viewer is ready and its canvas is not
//     blank (more than 1% of its pixels differ from the background).
//   node check.mjs three <model.glb> <screenshot.png>
//     loads the GLB with three.js's GLTFLoader (npm package three) in three.html, renders it
//     framed, and checks the same: no error, canvas not blank.
//
// CHROMIUM overrides the browser path (default /usr/bin/chromium).
import http from 'node:http';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const HERE = path.dirname(fileURLToPath(import.meta.url));
const TYPES = { '.html': 'text/html; charset=utf-8', '.js': 'text/javascript', '.mjs': 'text/javascript',
  '.glb': 'model/gltf-binary', '.png': 'image/png', '.jpg': 'image/jpeg', '.json': 'application/json' };
// Flags that work on this kind of machine (root, no GPU, closed network): software WebGL.
const FLAGS = ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
  '--disable-background-networking', '--disable-component-update', '--disable-sync',
  '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'];

function serve(root, extra) {
  const server = http.createServer((req, res) => {
    const url = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    let file = extra[url];
    if (!file) {
      file = path.join(root, url);
      if (!file.startsWith(root)) { res.writeHead(403); res.end(); return; }
    }
    fs.readFile(file, (err, data) => {
      if (err) { res.writeHead(404); res.end('not found'); return; }
      res.writeHead(200, { 'Content-Type': TYPES[path.extname(file)] || 'application/octet-stream' });
      res.end(data);
    });
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

async function main() {
  const [mode, target, shot] = process.argv.slice(2);
  if (!['report', 'three'].includes(mode) || !target || !shot) {
    console.error('usage: check.mjs report|three FILE SCREENSHOT.png');
    process.exit(2);
  }
  const file = path.resolve(target);
  if (!fs.existsSync(file)) {
    console.log(JSON.stringify({ ok: false, error: `no such file ${file}` }));
    process.exit(1);
  }
  const server = mode === 'report'
    ? await serve(path.dirname(file), {})
    : await serve(HERE, { '/model.glb': file });
  const port = server.address().port;
  const url = mode === 'report'
    ? `http://127.0.0.1:${port}/${encodeURIComponent(path.basename(file))}`
    : `http://127.0.0.1:${port}/three.html`;
  let browser;
  try {
    browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
      headless: true, args: FLAGS });
  } catch (e) {
    console.log(JSON.stringify({ ok: false, error: `cannot start Chromium: ${e.message}` }));
    server.close();
    process.exit(2);
  }
  const errors = [];
  const result = { mode, file, url };
  try {
    const page = await browser.newPage({ viewport: { width: 1200, height: 900 } });
    page.on('console', (m) => { if (m.type() === 'error') errors.push(`console: ${m.text()}`); });
    page.on('pageerror', (e) => errors.push(`page: ${e.message}`));
    page.on('requestfailed', (r) => errors.push(`request failed: ${r.url()} ${r.failure()?.errorText}`));
    await page.goto(url, { waitUntil: 'load', timeout: 60000 });
    await page.waitForFunction(() => ['ready', 'failed'].includes(document.body.dataset.viewer),
      null, { timeout: 90000 });
    result.viewer = await page.evaluate(() => document.body.dataset.viewer);
    const canvas = await page.$(mode === 'report' ? '#viewer' : 'canvas');
    result.nonBlank = Number(await canvas.evaluate((c) => c.dataset.nonBlank));
    result.details = await page.evaluate(() => window.frescoCheck || null);
    await canvas.scrollIntoViewIfNeeded();
    fs.mkdirSync(path.dirname(path.resolve(shot)), { recursive: true });
    await canvas.screenshot({ path: shot });
    result.screenshot = path.resolve(shot);
  } catch (e) {
    errors.push(`check: ${e.message}`);
  } finally {
    await browser.close();
    server.close();
  }
  result.errors = errors;
  result.ok = errors.length === 0 && result.viewer === 'ready' && result.nonBlank > 0.01;
  console.log(JSON.stringify(result));
  process.exit(result.ok ? 0 : 1);
}

main();
