// Drives the page of `python -m deploy web` in Debian's headless Chromium through playwright-core (no browser
// download): node driver.mjs PLAYWRIGHT_CORE_INDEX JOB.json OUT.json. JOB: {url, chromium, userDataDir, shots,
// qtg: {folder, clip, source, target}, walk: {folder, drag: [[x, y] pad fractions], speed, seconds},
// qn: {folder, clip, frame}, bad: {bvh, rigBvh, otherFolder}}. OUT: the page's results, messages, requests.
import { readFileSync, writeFileSync } from "node:fs";
import { pathToFileURL } from "node:url";

const [, , pwPath, jobPath, outPath] = process.argv;
const { chromium } = await import(pathToFileURL(pwPath).href);
const job = JSON.parse(readFileSync(jobPath, "utf8"));
const flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
  "--disable-background-networking", "--disable-component-update", "--disable-sync"];
const context = await chromium.launchPersistentContext(job.userDataDir, {
  executablePath: job.chromium, args: flags, headless: true, viewport: { width: 1100, height: 640 }, acceptDownloads: true,
});
const out = { requests: [], console: [], messages: {} };
const page = await context.newPage();
page.on("request", (r) => out.requests.push(r.url()));
page.on("console", (m) => { if (m.type() === "error") out.console.push(m.text()); });
page.on("pageerror", (e) => out.console.push(String(e)));
page.setDefaultTimeout(180000);

const last = () => page.evaluate(() => { const m = window.refimplWeb.messages; return m.length ? m[m.length - 1] : null; });
const count = () => page.evaluate(() => window.refimplWeb.messages.length);
async function waitMessage(before) {
  await page.waitForFunction((n) => window.refimplWeb.messages.length > n && !window.refimplWeb.busy, before);
  return last();
}
async function click(id) { const n = await count(); await page.click(id); return waitMessage(n); }
async function pick(id, label) { await page.selectOption(id, { label }); }

try {
  await page.goto(job.url);
  await page.waitForFunction(() => window.refimplWeb && window.refimplWeb.ready === true);
  // QTG
  const q = job.qtg;
  await pick("#qtg-folder", q.folder);
  await page.selectOption("#qtg-source-clip", q.clip);
  await page.selectOption("#qtg-target-clip", q.clip);
  await page.fill("#qtg-source-frame", String(q.source));
  await page.fill("#qtg-target-frame", String(q.target));
  out.messages.qtg = await click("#qtg-run");
  out.qtg = await page.evaluate(() => { const r = window.refimplWeb.results.qtg; return r && { rot: r.generated.rot, pos: r.generated.pos, start: r.start, stop: r.stop, window: r.window }; });
  await page.screenshot({ path: `${job.shots}/qtg.png` });
  const dl = page.waitForEvent("download");
  await page.click("#qtg-download");
  const file = await dl;
  await file.saveAs(`${job.shots}/transition.bvh`);
  // bad inputs
  const b = job.bad;
  let n = await count();
  await page.setInputFiles("#qtg-file", { name: "broken.bvh", mimeType: "text/plain", buffer: Buffer.from(b.bvh) });
  out.messages.malformed = await waitMessage(n);
  n = await count();
  await page.setInputFiles("#qtg-file", b.rigBvh);
  await waitMessage(n);
  out.messages.rig = await click("#qtg-run");
  await pick("#qtg-folder", b.otherFolder);
  out.messages.otherFolder = await click("#qtg-run");
  // walker
  await page.click("button[data-view=walk]");
  await pick("#walk-folder", job.walk.folder);
  const box = await page.locator("#walk-pad").boundingBox();
  const at = (p) => [box.x + p[0] * box.width, box.y + p[1] * box.height];
  await page.mouse.move(...at(job.walk.drag[0]));
  await page.mouse.down();
  await page.mouse.up();
  out.messages.onePoint = await click("#walk-run");
  await page.mouse.move(...at(job.walk.drag[0]));
  await page.mouse.down();
  for (const p of job.walk.drag.slice(1)) await page.mouse.move(...at(p), { steps: 8 });
  await page.mouse.up();
  await page.selectOption("#walk-speed", job.walk.speed);
  await page.fill("#walk-seconds", String(job.walk.seconds));
  out.messages.walk = await click("#walk-run");
  out.walk = await page.evaluate(() => window.refimplWeb.results.walk);
  await page.screenshot({ path: `${job.shots}/walk.png` });
  // QuaterNet
  await page.click("button[data-view=qn]");
  await pick("#qn-folder", job.qn.folder);
  await page.selectOption("#qn-clip", job.qn.clip);
  await page.fill("#qn-frame", String(job.qn.frame));
  out.messages.qn = await click("#qn-run");
  out.qn = await page.evaluate(() => window.refimplWeb.results.qn);
  await page.evaluate(() => { const s = document.getElementById("scrub"); s.value = s.max; s.dispatchEvent(new Event("input")); });
  await page.screenshot({ path: `${job.shots}/qn.png` });
} catch (err) {
  out.error = String(err && err.stack ? err.stack : err);
  try { out.lastMessage = await last(); await page.screenshot({ path: `${job.shots}/failure.png` }); } catch {}
}
await context.close();
writeFileSync(outPath, JSON.stringify(out));
