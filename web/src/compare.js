// Compare runs: overlaid curves (mean and ±1 std band across seeds of one configuration),
// Table I from each run's latest evaluation with the best cells in bold, and a diff of the
// runs' configurations.
import {
  asObject, chartControls, chartSettings, drawChart, el, errorBox, fmtNum, getJson, onChange,
} from './api.js';

const METRICS = ['success', 'episode_length', 'return', 'reward_split'];

export async function renderCompare(main) {
  const params = new URLSearchParams(window.location.search);
  const selected = new Set((params.get('runs') || '').split(',').map(Number).filter((n) => n > 0));
  let group = params.get('group') !== 'none';
  document.title = 'Compare · crm-grasp';
  const picker = el('div', { class: 'picker', id: 'run-picker' });
  const body = el('div');
  main.replaceChildren(
    el('h1', {}, 'Compare runs'),
    el('details', { class: 'card', open: selected.size === 0 },
      el('summary', {}, 'Pick runs'), picker),
    el('div', { class: 'toolbar' },
      chartControls(() => draw()),
      el('label', {}, el('input', {
        type: 'checkbox', name: 'group', checked: group,
        onchange: (e) => { group = e.target.checked; setUrl(); draw(); },
      }), ' one curve per configuration (mean ± std over seeds)')),
    body);

  function setUrl() {
    const query = new URLSearchParams();
    if (selected.size) query.set('runs', [...selected].join(','));
    if (!group) query.set('group', 'none');
    window.history.replaceState(null, '', `/compare${query.toString() ? `?${query}` : ''}`);
  }

  try {
    const { runs } = await getJson('/api/v1/runs');
    picker.replaceChildren(...runs.map((r) => {
      const spec = asObject(r.spec);
      return el('label', { class: 'pick' }, el('input', {
        type: 'checkbox', value: r.id, checked: selected.has(r.id),
        onchange: (e) => {
          if (e.target.checked) selected.add(r.id); else selected.delete(r.id);
          setUrl();
          draw();
        },
      }), ` #${r.id} ${r.algorithm} · ${r.task || (spec.tasks || []).join(',') || 'random'} · seed ${spec.seed ?? 0} · ${r.state}`);
    }));
    if (!runs.length) picker.append(el('p', { class: 'muted' }, 'No runs yet.'));
  } catch (err) {
    picker.replaceChildren(errorBox(err));
  }

  let figures = [];
  async function draw() {
    if (!selected.size) {
      body.replaceChildren(el('p', { class: 'muted' }, 'Pick two or more runs above, or select them on the jobs page.'));
      return;
    }
    const runs = [...selected].join(',');
    let data;
    try {
      data = await getJson(`/api/v1/compare?runs=${runs}`);
    } catch (err) {
      body.replaceChildren(errorBox(err));
      return;
    }
    figures = METRICS.map((metric) => el('figure', { class: 'chart', 'data-metric': metric }));
    body.replaceChildren(
      el('div', { class: 'charts' }, figures),
      el('h2', {}, 'Table I: success rate and episode length per objective'),
      tableOne(data.table),
      el('h2', {}, 'Configuration'),
      configDiff(data.config, data.runs));
    drawFigures();
  }

  function drawFigures() {
    const { smooth, x } = chartSettings();
    figures.forEach((figure) => drawChart(figure, {
      runs: [...selected].join(','), metric: figure.dataset.metric, smooth, x,
      group: group ? 'seeds' : 'none', width: 560, height: 300,
    }));
  }

  draw();
  onChange(drawFigures);
}

function tableOne(table) {
  const columns = table.columns;
  const head = el('tr', {}, el('th', {}, 'objective'), columns.map((c) => el('th', { colspan: 2 },
    el('a', { href: `/runs/${c.run}` }, `#${c.run} ${c.algorithm}`),
    c.report ? el('div', { class: 'muted', title: (c.tasks || []).join(', ') || 'random tasks' },
      `eval #${c.evaluation}, ${c.report.episodes} episodes${c.topology && c.topology !== 'task' ? `, topology ${c.topology}` : ''}`)
      : el('div', { class: 'muted' }, 'no evaluation: evaluate a checkpoint on its run page'))));
  const sub = el('tr', {}, el('th', {}), columns.map(() => [el('th', {}, 'success'), el('th', {}, 'length')]));
  const rows = [...table.objectives, 'overall'].map((objective) => {
    const best = table.best[objective] || { success: [], length: [] };
    return el('tr', { 'data-objective': objective, class: objective === 'overall' ? 'overall' : '' },
      el('th', {}, objective),
      columns.map((c, k) => {
        const row = !c.report ? null : objective === 'overall'
          ? { success_rate: c.report.success_rate, mean_episode_length: c.report.mean_episode_length }
          : c.report.per_objective[objective];
        return [
          el('td', { class: best.success.includes(k) ? 'best' : '', 'data-run': c.run, 'data-kind': 'success' }, row ? fmtNum(row.success_rate) : '–'),
          el('td', { class: best.length.includes(k) ? 'best' : '', 'data-run': c.run, 'data-kind': 'length' }, row ? fmtNum(row.mean_episode_length, 1) : '–'),
        ];
      }));
  });
  return el('table', { id: 'table-one', class: 'table-one' }, el('thead', {}, head, sub), el('tbody', {}, rows));
}

function configDiff(config, runs) {
  let only = true;
  const tbody = el('tbody');
  const fill = () => tbody.replaceChildren(...config.filter((r) => !only || r.differs).map((r) => el('tr', { class: r.differs ? 'differs' : '', 'data-key': r.key },
    el('th', {}, r.key), r.values.map((v) => el('td', {}, v === null ? '–' : v)))));
  fill();
  const same = config.filter((r) => !r.differs).length;
  return el('div', {},
    el('label', {}, el('input', { type: 'checkbox', checked: true, name: 'only-differences', onchange: (e) => { only = e.target.checked; fill(); } }),
      ` only what differs (${config.length - same} of ${config.length} keys differ)`),
    el('table', { id: 'config-diff' },
      el('thead', {}, el('tr', {}, el('th', {}, 'key'), runs.map((r) => el('th', {}, `#${r.id}`)))), tbody));
}
