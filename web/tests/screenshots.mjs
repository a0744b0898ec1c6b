// Photographs each dashboard page for the docs (scripts/dashboard-screenshots.sh seeds the
// data): node tests/screenshots.mjs BASE OUT-DIR RUN,RUN,... SWEEP
import { chromium } from 'playwright-core';

const [base, out, runList, sweep] = process.argv.slice(2);
const runs = runList.split(',');
const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage'],
});
const page = await browser.newPage({ viewport: { width: 1400, height: 900 } });
const drawn = () => page.waitForFunction(() => [...document.querySelectorAll('figure.chart')]
  .every((f) => f.querySelector('svg')), null, { timeout: 30000 });

await page.goto(`${base}/`);
await page.waitForSelector('#jobs tr[data-job]');
await page.screenshot({ path: `${out}/jobs.png`, fullPage: true });
await page.goto(`${base}/runs/${runs[0]}`);
await page.waitForSelector('figure.chart');
await drawn();
await page.screenshot({ path: `${out}/run.png`, fullPage: true });
await page.goto(`${base}/compare?runs=${runs.join(',')}`);
await page.waitForSelector('#table-one');
await drawn();
await page.screenshot({ path: `${out}/compare.png`, fullPage: true });
const topology = await (await fetch(`${base}/api/v1/topology`)).json();
const most = topology.checkpoints.sort((a, b) => b.forced_evaluations - a.forced_evaluations)[0];
await page.goto(`${base}/topology${most ? `?checkpoint_id=${most.checkpoint_id}` : ''}`);
await page.waitForSelector('#heatmap');
await page.screenshot({ path: `${out}/topology.png`, fullPage: true });
if (sweep) {
  await page.goto(`${base}/sweeps/${sweep}`);
  await page.waitForSelector('#sweep-table tbody tr');
  await drawn();
  await page.screenshot({ path: `${out}/sweep.png`, fullPage: true });
}
await page.goto(`${base}/models`);
await page.waitForSelector('#models tr[data-checkpoint]');
await page.waitForSelector('#evaluations tbody tr');
await page.screenshot({ path: `${out}/models.png`, fullPage: true });
await page.goto(`${base}/runs/999999`);
await page.waitForSelector('.not-found');
await page.screenshot({ path: `${out}/not-found.png` });
await browser.close();
