// Browser tests of the dashboard in real headless Chromium (Debian's, driven by
// playwright-core). Started by `tests/web.rs`, which runs the real coordinator and a worker,
// seeds runs and evaluations through the API and passes what it made in the environment:
//   CRM_BASE         the coordinator's URL (http://127.0.0.1:PORT)
//   CRM_SEED         JSON: {"runs": [a, b, c], "group": [a, b]} (a and b: two seeds of one config)
//   CRM_SCREENSHOTS  optional folder for a PNG of each page
// Exits non-zero with the failed check's message.
import assert from 'node:assert/strict';
import { mkdirSync } from 'node:fs';
import { chromium } from 'playwright-core';

const base = process.env.CRM_BASE;
const seed = JSON.parse(process.env.CRM_SEED || '{}');
const shots = process.env.CRM_SCREENSHOTS;
const [runA, runB, runC] = seed.runs || [];
assert.ok(base && runA && runB && runC, 'CRM_BASE and CRM_SEED must be set (see tests/web.rs)');
if (shots) mkdirSync(shots, { recursive: true });

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage'],
});
const page = await browser.newPage({ viewport: { width: 1400, height: 1000 } });
const problems = [];
page.on('pageerror', (err) => problems.push(`page error: ${err.message}`));
// A refused request logs "Failed to load resource" in the console: the checks that provoke
// refusals on purpose (the form's 400s, the not-found pages' 404s) say so, and in every other
// check any response of 400 or more (a missing icon, a broken link) is a problem, as is any
// other console error.
let current = { name: '', refusals: false };
page.on('console', (msg) => {
  if (msg.type() === 'error' && !msg.text().startsWith('Failed to load resource')) problems.push(`console: ${msg.text()}`);
});
page.on('response', (response) => {
  if (response.status() >= 400 && !current.refusals) {
    problems.push(`${response.status()} ${response.url()} (in "${current.name}")`);
  }
});

async function shot(name) {
  if (shots) await page.screenshot({ path: `${shots}/${name}.png`, fullPage: true });
}

async function api(path) {
  const response = await fetch(`${base}${path}`);
  assert.equal(response.status, 200, `${path}: ${response.status}`);
  return response.json();
}

/** Waits until every chart in the page has drawn an SVG with at least one line. */
async function chartsDrawn(count) {
  await page.waitForFunction((n) => {
    const figures = [...document.querySelectorAll('figure.chart')];
    return figures.length >= n && figures.every((f) => f.querySelector('svg polyline'));
  }, count, { timeout: 20000 });
}

const checks = [];
/** A check; `refusals`: it provokes 4xx responses on purpose. */
function check(name, body, { refusals = false } = {}) { checks.push([{ name, refusals }, body]); }

check('jobs list shows the seeded runs live', async () => {
  await page.goto(`${base}/`);
  await page.waitForSelector(`#jobs tr[data-job="${runA}"]`);
  for (const id of [runA, runB, runC]) {
    const state = await page.getAttribute(`#jobs tr[data-job="${id}"]`, 'data-state');
    assert.equal(state, 'succeeded', `run ${id}`);
  }
  await page.waitForFunction(() => document.getElementById('live').textContent === 'live');
  const text = await page.textContent(`#jobs tr[data-job="${runC}"]`);
  assert.match(text, /lppo/);
  assert.match(text, /mouse-press/);
  await shot('jobs');
});

check('filters narrow the list', async () => {
  await page.selectOption('select[name="filter-algorithm"]', 'lppo');
  await page.waitForFunction(() => [...document.querySelectorAll('#jobs tbody tr[data-job]')]
    .every((tr) => tr.children[4].textContent === 'lppo'));
  const rows = await page.$$eval('#jobs tbody tr[data-job]', (trs) => trs.map((tr) => tr.dataset.job));
  assert.ok(rows.includes(String(runC)));
  assert.ok(!rows.includes(String(runA)));
  assert.match(page.url(), /algorithm=lppo/);
  await page.selectOption('select[name="filter-algorithm"]', '');
  await page.waitForSelector(`#jobs tr[data-job="${runA}"]`);
});

check('the form shows API errors next to the field, then queues a job that appears', async () => {
  // The form offers the coordinator's worlds (this one has only the built-in world).
  assert.deepEqual(await page.$$eval('#f-world option', (os) => os.map((o) => o.value)), ['crm']);
  await page.fill('#f-steps', '-5');
  await page.click('#submit-job button[type=submit]');
  await page.waitForSelector('[data-error-for="steps"]:not(:empty)');
  assert.match(await page.textContent('[data-error-for="steps"]'), /steps/);
  assert.ok(await page.$('#f-steps.invalid'));
  await shot('jobs-form-error');

  await page.fill('#f-steps', '3000');
  await page.fill('#f-config', '{"gamma": 2}');
  await page.click('#submit-job button[type=submit]');
  await page.waitForFunction(() => /config\.gamma/.test(document.querySelector('[data-error-for="config"]').textContent));
  assert.equal(await page.textContent('[data-error-for="steps"]'), '');

  await page.fill('#f-config', '{"learning_rate": 0.0003}');
  await page.fill('#f-record_connect', 'not-a-viewer');
  await page.click('#submit-job button[type=submit]');
  await page.waitForFunction(() => /record\.connect/.test(document.querySelector('[data-error-for="record_connect"]').textContent));
  await page.fill('#f-record_connect', '');
  await page.fill('#f-imitation', '0');
  await page.click('#submit-job button[type=submit]');
  await page.waitForFunction(() => /imitation\.episodes/.test(document.querySelector('[data-error-for="imitation"]').textContent));
  await page.fill('#f-imitation', '40');
  await page.fill('#f-record_every', '5');
  await page.fill('#f-hold_s', '0');
  await page.click('#submit-job button[type=submit]');
  await page.waitForFunction(() => /between 0\.1 and 8/.test(document.querySelector('[data-error-for="hold_s"]').textContent));
  await page.fill('#f-hold_s', '1.5');
  await page.selectOption('#f-tasks', ['valve-twist']);
  await page.selectOption('#f-objective', 'learned');
  await page.check('#f-curriculum');
  await page.click('#submit-job button[type=submit]');
  const ok = await page.waitForSelector('.message .ok');
  const id = Number((await ok.textContent()).match(/Job (\d+) queued/)[1]);
  const row = `#jobs tr[data-job="${id}"]`;
  await page.waitForSelector(row);
  assert.equal(await page.getAttribute(row, 'data-state'), 'queued');
  assert.match(await page.textContent(row), /valve-twist/);
  const stored = await api(`/api/v1/jobs/${id}`);
  assert.equal(stored.spec.steps, 3000);
  assert.deepEqual(stored.spec.tasks, ['valve-twist']);
  assert.equal(stored.spec.record.every, 5);
  assert.equal(stored.spec.imitation.episodes, 40);
  assert.equal(stored.spec.objective, 'learned');
  assert.equal(stored.spec.curriculum, true);
  assert.equal(stored.spec.hold_s, 1.5);

  // Cancel it from its row; the list follows. (A selector, not the row's handle: live updates
  // redraw the list while a worker reports.)
  await page.click(`#jobs tr[data-job="${id}"] button:has-text("Cancel")`);
  await page.waitForSelector(`#jobs tr[data-job="${id}"][data-state="cancelled"]`);
}, { refusals: true });

// A browser with a window asks every page for its icon (headless Chromium does not, so it is
// checked here): without a declared one, /favicon.ico is a 404 in the console of every page.
check('every page declares an icon that loads', async () => {
  for (const path of ['/', `/runs/${runA}`, `/compare?runs=${runA},${runB}`, '/sweeps', '/topology', '/models']) {
    await page.goto(`${base}${path}`);
    const href = await page.getAttribute('link[rel="icon"]', 'href');
    assert.ok(href, `${path}: no <link rel="icon">`);
    const icon = await fetch(new URL(href, base));
    assert.equal(icon.status, 200, `${path}: ${href}`);
    assert.match(icon.headers.get('content-type'), /^image\//);
  }
});

check('a run page draws its curves, lists checkpoints and evaluations', async () => {
  await page.goto(`${base}/runs/${runA}`);
  await page.waitForSelector('h1:has-text("Run #")');
  assert.match(await page.textContent('dl.facts'), /world\s*crm/);
  await chartsDrawn(9);
  // The per-task chart names the run's task (the training log's `task_success`).
  assert.match(await page.textContent('figure[data-metric="task_success"] svg'), /mouse-press/);
  const rows = await page.$$('#checkpoints tr[data-checkpoint]');
  assert.ok(rows.length >= 1, 'a checkpoint row');
  const href = await page.getAttribute('#checkpoints tr[data-checkpoint] a', 'href');
  const download = await fetch(`${base}${href}`);
  assert.equal(download.status, 200);
  // "How made" shows the checkpoint's lineage: this run's one stage, as its job asked.
  await page.click('#checkpoints tr[data-checkpoint] button:has-text("How made")');
  await page.waitForSelector('#lineage tbody tr[data-stage="1"]');
  const stage = await page.$$eval('#lineage tbody tr[data-stage="1"] td', (tds) => tds.map((td) => td.textContent));
  assert.deepEqual(stage.slice(1, 3), ['train', 'crm-ppo'], JSON.stringify(stage));
  assert.equal(stage[5], '0', JSON.stringify(stage));
  assert.equal((await page.$$('#lineage tbody tr')).length, 1);
  assert.ok((await page.$$('#evaluations tbody tr')).length >= 1, 'an evaluation row');
  // A finished evaluation lists its success per task and how its episodes ended.
  const runData = await api(`/api/v1/runs/${runA}`);
  const done = runData.evaluations.find((e) => e.result && Object.keys(e.result.per_task || {}).length);
  assert.ok(done, 'an evaluation with per-task results');
  const [task, row] = Object.entries(done.result.per_task)[0];
  const item = await page.textContent(`#evaluations li[data-task="${task}"]`);
  assert.ok(item.includes(`${task} ${row.success_rate.toFixed(2)}`), item);
  // ... and, for a task with failures, each cause with its count.
  assert.ok(row.outcomes, 'per-task outcomes');
  const failed = Object.entries(row.outcomes).filter(([outcome]) => outcome !== 'success');
  for (const [outcome, n] of failed) {
    assert.ok(item.includes(`${outcome.replace(/^failure \((.*)\)$/, '$1')} ${n}`), item);
  }
  assert.equal(item.includes(':'), failed.length > 0, item);
  assert.ok((await page.textContent('#evaluations td.outcomes')).length > 0, 'outcomes shown');
  // Run a records its first two episodes: its episode list shows them with their stage
  // transitions (not an evaluation's episodes).
  await page.waitForSelector('#episodes tbody tr');
  const episodes = await page.$$eval('#episodes tbody tr',
    (trs) => trs.map((tr) => [...tr.querySelectorAll('td')].map((td) => td.textContent)));
  const shown = JSON.stringify(episodes);
  assert.equal(episodes.length, 2, shown);
  for (const [task, success, length, ret] of episodes) {
    assert.equal(task, 'mouse-press', shown);
    assert.ok(['yes', 'no'].includes(success), shown);
    assert.ok(Number(length) >= 1 && Number(length) <= 600, shown);
    assert.ok(Number.isFinite(Number(ret.replace(/,/g, ''))), shown);
  }
  assert.doesNotMatch(await page.textContent('#episodes-section'), /From evaluation/);
  // Run a records every episode: the section offers the file and the viewer command.
  await page.waitForSelector('#recording a[href$="/recording"]');
  assert.match(await page.textContent('#recording'), new RegExp(`rerun http://.*/api/v1/jobs/${runA}/recording`));
  // Its evaluation's video plays: the GIF loads at its stored size, with its caption.
  const video = runData.videos[0];
  assert.ok(video && video.frames > 1, JSON.stringify(runData.videos));
  await page.waitForFunction((w) => {
    const img = document.querySelector('#videos figure img');
    return img && img.complete && img.naturalWidth === w;
  }, video.width);
  assert.match(await page.textContent('#videos figcaption'), new RegExp(`Evaluation #${video.job_id}: first 1 episode, ${video.frames} frames`));
  // Evaluate a checkpoint with the mean action and a video from the page: the job asks for both.
  await page.fill('input[name="eval-episodes"]', '3');
  await page.check('input[name="eval-deterministic"]');
  await page.check('input[name="eval-video"]');
  await page.click('#checkpoints tr[data-checkpoint] button:has-text("Evaluate")');
  await page.waitForSelector('.message .ok:has-text("Evaluation job")');
  const queued = Number((await page.textContent('.message .ok')).match(/Evaluation job (\d+)/)[1]);
  const job = await api(`/api/v1/jobs/${queued}`);
  assert.equal(job.spec.deterministic, true);
  assert.equal(job.spec.episodes, 3);
  assert.deepEqual(job.spec.video, { episodes: 3, width: 320, height: 240 });
  // No worker runs now: cancel it so the other pages see only finished evaluations.
  const cancelled = await fetch(`${base}/api/v1/jobs/${queued}/cancel`, { method: 'POST' });
  assert.equal(cancelled.status, 200);
  // The episode table shows an evaluation's stage transitions.
  assert.ok((await page.$$('#episodes tbody tr')).length >= 1, 'episode rows');
  // Another x axis redraws the charts.
  await page.selectOption('select[name="x"]', 'episodes');
  await page.waitForFunction(() => document.querySelector('figure[data-metric="success"] svg')?.textContent.includes('episodes'));
  await chartsDrawn(9);
  await page.selectOption('select[name="x"]', 'steps');
  await chartsDrawn(9);
  await shot('run');
});

check('a run that does not exist shows a not-found page with status 404', async () => {
  const response = await page.goto(`${base}/runs/987654`);
  assert.equal(response.status(), 404);
  await page.waitForSelector('.not-found h1');
  assert.match(await page.textContent('.not-found'), /Run 987654 does not exist/);
  const other = await page.goto(`${base}/no/such/page`);
  assert.equal(other.status(), 404);
  await page.waitForSelector('.not-found');
  await shot('not-found');
}, { refusals: true });

check('comparing runs overlays curves with a seed band, Table I and the config diff', async () => {
  await page.goto(`${base}/compare?runs=${runA},${runB},${runC}`);
  await page.waitForSelector('#table-one');
  await chartsDrawn(4);
  // Runs a and b share a configuration: one mean curve with a band.
  const band = await page.$$eval('figure[data-metric="success"] svg polygon', (p) => p.length);
  assert.ok(band >= 1, 'a seed band');
  const legend = await page.textContent('figure[data-metric="success"] svg');
  assert.match(legend, /x2 seeds/);

  // Table cells equal the API's numbers; the best cell of each row is bold.
  const data = await api(`/api/v1/compare?runs=${runA},${runB},${runC}`);
  for (const column of data.table.columns) {
    const cell = await page.textContent(`#table-one tr[data-objective="overall"] td[data-run="${column.run}"][data-kind="success"]`);
    assert.equal(cell, column.report.success_rate.toFixed(2), `overall success of run ${column.run}`);
    const press = await page.textContent(`#table-one tr[data-objective="press"] td[data-run="${column.run}"][data-kind="success"]`);
    assert.equal(press, column.report.per_objective.press.success_rate.toFixed(2));
  }
  const best = await page.$$eval('#table-one tr[data-objective="overall"] td.best[data-kind="success"]', (tds) => tds.map((td) => td.dataset.run));
  const expected = data.table.best.overall.success.map((k) => String(data.table.columns[k].run));
  assert.deepEqual(best, expected);
  const weight = await page.$eval('#table-one td.best', (td) => getComputedStyle(td).fontWeight);
  assert.equal(weight, '700');

  // The diff shows only differing keys by default: the seed and the algorithm differ.
  const keys = await page.$$eval('#config-diff tbody tr', (trs) => trs.map((tr) => [tr.dataset.key, tr.className]));
  const differing = keys.map(([k]) => k);
  assert.ok(differing.includes('seed'), differing.join(','));
  assert.ok(differing.includes('algorithm'), differing.join(','));
  assert.ok(keys.every(([, c]) => c === 'differs'));
  await page.uncheck('input[name="only-differences"]');
  const all = await page.$$eval('#config-diff tbody tr', (trs) => trs.length);
  assert.ok(all > differing.length, 'equal keys appear when asked');
  await shot('compare');

  // Without grouping every run is its own curve.
  await page.uncheck('input[name="group"]');
  await page.waitForFunction(() => !/x2 seeds/.test(document.querySelector('figure[data-metric="success"] svg')?.textContent || 'x2 seeds'));
  assert.match(page.url(), /group=none/);
});

check('the topology page shows picks per task and a heat map of forced topologies', async () => {
  await page.goto(`${base}/topology`);
  await page.waitForSelector('#topology-tasks tbody tr');
  const data = await api('/api/v1/topology');
  assert.equal((await page.$$('#topology-tasks tbody tr')).length, data.tasks.length);
  assert.equal(data.tasks.length, 26);
  assert.match(await page.textContent('.summary'), new RegExp(`${data.picked_as_assigned} of 26`));
  const filled = await page.$$eval('#heatmap td[data-cell]:not(.empty)', (tds) => tds.map((td) => td.dataset.cell));
  const expected = data.results.map((r) => `${r.objective}|${r.topology}`);
  assert.deepEqual(filled.sort(), expected.sort());
  assert.ok(filled.length >= 2, 'forced-topology evaluations fill cells');
  // One checkpoint's evaluations only: the cells follow the API's for that checkpoint.
  const [first] = data.checkpoints;
  await page.selectOption('select[name="checkpoint"]', String(first.checkpoint_id));
  const one = await api(`/api/v1/topology?checkpoint_id=${first.checkpoint_id}`);
  const cellsOf = (d) => d.results.map((r) => `${r.objective}|${r.topology}|${r.success_rate.toFixed(2)}`).sort();
  // Wait for the redraw itself: both views can fill the same number of cells.
  const cellsShown = () => page.$$eval('#heatmap td[data-cell]:not(.empty)', (tds) => tds.map((td) => `${td.dataset.cell}|${td.firstChild.textContent}`).sort());
  await page.waitForFunction((want) => {
    const got = [...document.querySelectorAll('#heatmap td[data-cell]:not(.empty)')]
      .map((td) => `${td.dataset.cell}|${td.firstChild.textContent}`).sort();
    return JSON.stringify(got) === JSON.stringify(want);
  }, cellsOf(one), { timeout: 10000 }).catch(() => {});
  assert.deepEqual(await cellsShown(), cellsOf(one));
  assert.match(page.url(), new RegExp(`checkpoint_id=${first.checkpoint_id}`));
  await shot('topology');
});

check('the models page lists the shipped model, refuses a file that is no checkpoint and evaluates a model', async () => {
  await page.goto(`${base}/models`);
  await page.waitForSelector('#models tr[data-checkpoint]');
  assert.match(await page.textContent('#models tr[data-checkpoint]'), /crm-ppo/);
  const id = Number(await page.getAttribute('#models tr[data-checkpoint]', 'data-checkpoint'));
  await page.setInputFiles('#model-file', { name: 'notes.safetensors', mimeType: 'application/octet-stream', buffer: Buffer.from('hello') });
  await page.click('#upload-model');
  await page.waitForSelector('.message .error');
  assert.match(await page.textContent('.message'), /body: not a safetensors file/);
  // The shipped file itself is the same model, not a second one.
  await page.setInputFiles('#model-file', process.env.CRM_MODEL);
  await page.click('#upload-model');
  await page.waitForSelector('#uploaded');
  assert.match(await page.textContent('#uploaded'), new RegExp(`model ${id} `));
  assert.equal(await page.$$eval('#models tr[data-checkpoint]', (trs) => trs.length), 1);
  await page.fill('input[name="eval-episodes"]', '5');
  await page.click('#models tr[data-checkpoint] button:has-text("Evaluate")');
  await page.waitForSelector('.message .ok:has-text("Evaluation job")');
  const job = Number((await page.textContent('.message .ok')).match(/job (\d+)/)[1]);
  const queued = await api(`/api/v1/jobs/${job}`);
  assert.equal(queued.checkpoint_id, id);
  assert.equal(queued.spec.episodes, 5);
  // No worker runs now: cancel it; the page's evaluations follow live.
  const cancelled = await fetch(`${base}/api/v1/jobs/${job}/cancel`, { method: 'POST' });
  assert.equal(cancelled.status, 200);
  await page.waitForSelector('#evaluations .badge.cancelled');
  await shot('models');
}, { refusals: true });

check('a sweep page shows its progress, curves per configuration and Table I with the best cells bold', async () => {
  await page.goto(`${base}/sweeps`);
  await page.waitForSelector(`#sweeps tr[data-sweep="${seed.sweep}"]`);
  assert.match(await page.textContent(`#sweeps tr[data-sweep="${seed.sweep}"]`), /browser sweep/);
  await page.click(`#sweeps tr[data-sweep="${seed.sweep}"] a`);
  await page.waitForSelector('#sweep-table tbody tr');
  assert.match(await page.textContent('#sweep-progress'), /4 of 4 jobs finished/);
  const api_ = await api(`/api/v1/sweeps/${seed.sweep}`);
  const rows = await page.$$eval('#sweep-table tbody tr', (trs) => trs.map((tr) => tr.children[0].textContent));
  assert.deepEqual(rows, api_.table.rows.map((r) => r.label));
  // The overall success cell reads the API's mean ± std.
  const first = api_.table.rows[0].overall.success;
  const shown = await page.textContent('#sweep-table tbody tr[data-row="0"] td:nth-child(4)');
  assert.equal(shown, `${first.mean.toFixed(2)} ± ${first.std.toFixed(2)}`);
  assert.ok(await page.$('#sweep-table td.best'), 'a best cell is bold');
  await chartsDrawn(2);
  const href = await page.getAttribute('#compare-sweep', 'href');
  const trainIds = api_.jobs.filter((j) => j.kind === 'train').map((j) => j.id);
  assert.equal(href, `/compare?runs=${trainIds.join(',')}`);
  assert.equal(await page.isDisabled('#cancel-sweep'), true);
  await shot('sweep');
});

// Last: it removes run C (the other checks use it).
check('a finished run shows its disk use and can be deleted from its page', async () => {
  const before = await api(`/api/v1/runs/${runC}`);
  assert.ok(before.disk_bytes > 0, 'the run stores checkpoints');
  await page.goto(`${base}/runs/${runC}`);
  await page.waitForSelector('h1:has-text("Run #")');
  assert.match(await page.textContent('dl.facts'), /disk\s*[\d.]+ (KiB|MiB|GiB)/);
  assert.equal(await page.isDisabled('#delete-run'), false);
  page.once('dialog', (dialog) => dialog.accept());
  await page.click('#delete-run');
  await page.waitForSelector('#deleted');
  assert.match(await page.textContent('#deleted'), new RegExp(`Run #${runC} deleted`));
  const gone = await fetch(`${base}/api/v1/runs/${runC}`);
  assert.equal(gone.status, 404);
  for (const id of [runA, runB]) await api(`/api/v1/runs/${id}`);
  const jobs = await api('/api/v1/jobs?limit=10000');
  assert.ok(!jobs.jobs.some((j) => j.id === runC), 'the run left the jobs list');
  await shot('deleted');
}, { refusals: true });

// Last: it frees the busy worker.
check('a job building demonstrations shows its phase in the list and on its page', async () => {
  const id = seed.phase_job;
  await page.goto(`${base}/`);
  await page.waitForSelector(`#jobs tr[data-job="${id}"] .progress.phase`);
  assert.match(await page.textContent(`#jobs tr[data-job="${id}"] .progress`), /demonstrations \d+%/);
  await page.goto(`${base}/runs/${id}`);
  await page.waitForSelector('#phase');
  assert.match(await page.textContent('#phase'), /^demonstrations: [\d,]+ of 100,000$/);
  await shot('phase');
  const cancelled = await fetch(`${base}/api/v1/jobs/${id}/cancel`, { method: 'POST' });
  assert.equal(cancelled.status, 200);
});

let failed = 0;
for (const [what, body] of checks) {
  const { name } = what;
  current = what;
  try {
    await body();
    console.log(`ok - ${name}`);
  } catch (err) {
    failed += 1;
    console.log(`FAILED - ${name}\n  ${err.stack || err}`);
    await page.screenshot({ path: `${shots || '/tmp'}/failed-${failed}.png`, fullPage: true }).catch(() => {});
  }
}
if (problems.length) {
  failed += 1;
  console.log(`FAILED - the pages logged errors:\n  ${problems.join('\n  ')}`);
}
await browser.close();
console.log(`${checks.length - failed} of ${checks.length} browser checks passed`);
process.exit(failed ? 1 : 0);
