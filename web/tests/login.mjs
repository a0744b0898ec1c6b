// The dashboard on a coordinator with tokens, in real headless Chromium (Debian's, driven by
// playwright-core). Started by `tests/web.rs`, which runs the coordinator with a read and a
// submit token and passes:
//   CRM_BASE          the coordinator's URL (http://127.0.0.1:PORT)
//   CRM_READ_TOKEN    the token with the read scope
//   CRM_SUBMIT_TOKEN  the token with the submit scope
//   CRM_CHECKPOINT    the id of a registered checkpoint (its download link must work)
// The dashboard asks for a token once (its login page), then lists jobs, follows live updates
// (a job submitted elsewhere appears without a reload) and downloads a checkpoint; a reload
// keeps it signed in. Exits non-zero with the failed check's message.
import assert from 'node:assert/strict';
import { chromium } from 'playwright-core';

const base = process.env.CRM_BASE;
const readToken = process.env.CRM_READ_TOKEN;
const submitToken = process.env.CRM_SUBMIT_TOKEN;
const checkpoint = process.env.CRM_CHECKPOINT;
assert.ok(base && readToken && submitToken && checkpoint, 'see tests/web.rs for the environment');

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage'],
});
try {
  const context = await browser.newContext({ acceptDownloads: true });
  const page = await context.newPage();
  const errors = [];
  page.on('pageerror', (err) => errors.push(err.message));

  // Signed out: the login page, and no data.
  await page.goto(`${base}/`);
  await page.waitForSelector('form.login #login-token');
  assert.equal(await page.locator('#jobs').count(), 0, 'no jobs table before signing in');

  // A wrong token: still the login page, which says so.
  await page.fill('#login-token', 'not-a-token');
  await page.click('form.login button[type=submit]');
  await page.waitForSelector('form.login');
  assert.match(await page.textContent('form.login'), /did not accept/);

  // The read token: the jobs list.
  await page.fill('#login-token', readToken);
  await page.click('form.login button[type=submit]');
  await page.waitForSelector('#jobs');
  const live = page.locator('#live.on');
  await live.waitFor({ timeout: 10000 });

  // A job submitted by another client appears by the event stream, without a reload.
  const body = {
    kind: 'train', algorithm: 'crm-ppo', task: 'mouse-press', steps: 2048, seed: 5, envs: 1,
  };
  const response = await fetch(`${base}/api/v1/jobs`, {
    method: 'POST',
    headers: { 'content-type': 'application/json', authorization: `Bearer ${submitToken}` },
    body: JSON.stringify(body),
  });
  assert.equal(response.status, 201, `submit: ${response.status}`);
  const job = await response.json();
  await page.waitForSelector(`#jobs tr[data-job="${job.id}"]`, { timeout: 20000 });

  // A download link carries the read cookie.
  await page.goto(`${base}/models`);
  const [download] = await Promise.all([
    page.waitForEvent('download'),
    page.click(`a[href="/api/v1/checkpoints/${checkpoint}/download"]`),
  ]);
  assert.equal(await download.failure(), null, 'the download failed');

  // A reload stays signed in.
  await page.goto(`${base}/`);
  await page.waitForSelector(`#jobs tr[data-job="${job.id}"]`);
  assert.equal(await page.locator('form.login').count(), 0);
  assert.deepEqual(errors, [], `page errors: ${errors.join('; ')}`);
  console.log('login: ok');
} finally {
  await browser.close();
}
