// Plots: any signals over the whole session, several to a chart (one axis per unit), the
// charts' cursors in step with each signal's value at the cursor, zoom (drag across a
// chart; double-click to zoom out), pause, and each chart's data as CSV or MCAP.
//
// A chart starts from the gateway's history of its signals since the session began
// (/api/history: the whole session, coarser the longer it runs) and goes on with the live
// stream's samples at full rate. Memory is bounded: past MAX_POINTS the chart takes the
// history again (which has everything up to now at the history's resolution) and keeps
// only what came after it.
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';
import { get } from '../api';
import type { SignalInfo } from '../live';
import type { Ctx, View } from '../view';
import { h, num, setText } from '../util';
import { mcapOf } from '../mcap';

const DEFAULT: string[][] = [['Vehicle.Speed'], ['Vehicle.Powertrain.CombustionEngine.Speed']];
const KEY = 'autoplug-plots-charts';
/** Points of a chart before it takes the history again. */
const MAX_POINTS = 40_000;
/** A pause in the samples longer than this (the page was hidden) takes the history again, s. */
const RESYNC_S = 2;

const WINDOWS: [string, number | null][] = [['1 min', 60], ['10 min', 600], ['Session', null]];

interface Chart {
  paths: string[];
  box: HTMLElement;
  plotBox: HTMLElement;
  legend: HTMLElement;
  values: HTMLElement[];
  cursorT: HTMLElement;
  t: number[];
  vs: (number | null)[][];
  /** Bus time of the session's first sample (from the history), s. */
  start: number | null;
  plot: uPlot | null;
  /** Samples are taken only once the history is in (they follow it). */
  loading: boolean;
  /** The user zoomed: the x range stays where it was put. */
  zoomed: boolean;
}

function color(i: number): string {
  const hues = [205, 25, 140, 280, 50, 330, 175, 0];
  return `hsl(${hues[i % hues.length]} 75% 45%)`;
}

function load(): string[][] {
  try {
    const saved = JSON.parse(localStorage.getItem(KEY) ?? 'null');
    if (Array.isArray(saved) && saved.every((c) => Array.isArray(c) && c.every((p) => typeof p === 'string'))) return saved.length ? saved : DEFAULT;
  } catch {
    // A damaged setting: the default charts.
  }
  return DEFAULT;
}

function download(name: string, blob: Blob): void {
  const a = h('a', { href: URL.createObjectURL(blob), download: name });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10_000);
}

export function plotsView(ctx: Ctx): View {
  const { live } = ctx;
  let layout = load();
  let active = 0;
  let paused = false;
  let windowS: number | null = Number(localStorage.getItem(`${KEY}-window`)) || null;
  const charts: Chart[] = [];
  const chartsEl = h('div', { class: 'charts' });
  const picker = h('div', { class: 'picker' });
  const filter = h('input', { type: 'search', placeholder: 'filter signals', class: 'filter', 'aria-label': 'filter signals' });
  const target = h('div', { class: 'muted small', 'data-testid': 'plot-target' });
  const pause = h('button', { class: 'btn', 'data-testid': 'pause' }, 'Pause');
  pause.addEventListener('click', () => {
    paused = !paused;
    pause.classList.toggle('active', paused);
    pause.textContent = paused ? 'Resume' : 'Pause';
  });
  const newChart = h('button', { class: 'btn', 'data-testid': 'new-chart', title: 'a new chart; the signals you tick go into it' }, 'New chart');
  newChart.addEventListener('click', () => {
    layout.push([]);
    active = layout.length - 1;
    save();
    rebuild();
  });
  const windowButtons = WINDOWS.map(([label, s]) => {
    const b = h('button', { class: 'btn', 'data-testid': `window-${s ?? 'session'}` }, label);
    b.addEventListener('click', () => {
      windowS = s;
      localStorage.setItem(`${KEY}-window`, String(s ?? ''));
      for (const c of charts) c.zoomed = false;
      markWindow();
      draw(true);
    });
    return b;
  });
  function markWindow(): void {
    windowButtons.forEach((b, i) => b.classList.toggle('active', WINDOWS[i][1] === windowS));
  }
  markWindow();
  const el = h('section', { class: 'plots' },
    h('aside', { class: 'card side' }, h('h3', { text: 'Signals' }), target, filter, picker),
    h('div', { class: 'main-col' },
      h('div', { class: 'toolbar' }, pause, h('span', { class: 'btn-group' }, ...windowButtons), newChart,
        h('span', { class: 'muted small', text: 'Drag across a chart to zoom, double-click to zoom out.' })),
      chartsEl),
  );
  const sync = uPlot.sync('plots');

  function save(): void {
    localStorage.setItem(KEY, JSON.stringify(layout));
  }

  function buildPicker(): void {
    picker.replaceChildren();
    setText(target, layout.length ? `Ticked signals go to chart ${active + 1} (click a chart to choose another).` : 'Tick a signal to plot it.');
    const f = filter.value.toLowerCase();
    const inActive = layout[active] ?? [];
    for (const s of live.catalog) {
      if (f && !s.path.toLowerCase().includes(f) && !s.name.toLowerCase().includes(f)) continue;
      const box = h('input', { type: 'checkbox', checked: inActive.includes(s.path), 'data-path': s.path });
      box.addEventListener('change', () => {
        if (layout.length === 0) {
          layout.push([]);
          active = 0;
        }
        const paths = layout[active];
        layout[active] = box.checked ? [...paths, s.path] : paths.filter((p) => p !== s.path);
        save();
        rebuild();
      });
      picker.append(h('label', { class: 'pick', title: s.path }, box, h('span', { text: s.name }), h('span', { class: 'muted small', text: s.unit })));
    }
  }
  filter.addEventListener('input', buildPicker);

  /** Charts as the layout says (empty charts other than the active one go). */
  function rebuild(): void {
    layout = layout.filter((paths, i) => paths.length > 0 || i === active);
    active = Math.min(active, Math.max(0, layout.length - 1));
    save();
    for (const c of charts) {
      c.plot?.destroy();
      c.box.remove();
    }
    charts.length = 0;
    layout.forEach((paths, i) => {
      const known = paths.filter((p) => live.byPath.has(p));
      charts.push(makeChart(known, i));
    });
    buildPicker();
  }

  function makeChart(paths: string[], index: number): Chart {
    const plotBox = h('div', { class: 'plot-area' });
    const legend = h('div', { class: 'plot-legend' });
    const cursorT = h('span', { class: 'muted small mono', 'data-testid': 'cursor-t' });
    const csv = h('button', { class: 'btn small', 'data-testid': 'export-csv', title: 'what the chart shows, as CSV' }, 'CSV');
    const mcap = h('button', { class: 'btn small', 'data-testid': 'export-mcap', title: 'what the chart shows, as MCAP (Foxglove, PlotJuggler)' }, 'MCAP');
    const remove = h('button', { class: 'btn small', title: 'remove this chart' }, '×');
    const infos = paths.map((p) => live.byPath.get(p)!);
    const box = h('div', { class: `card chart${index === active ? ' active' : ''}`, 'data-testid': `chart-${index}`, 'data-paths': paths.join(',') },
      h('div', { class: 'chart-head' },
        h('strong', { text: infos.length ? infos.map((s) => s.name).join(' · ') : `Chart ${index + 1}: tick signals on the left` }),
        cursorT, h('span', { class: 'spacer' }), csv, mcap, remove),
      plotBox, legend);
    chartsEl.append(box);
    const chart: Chart = { paths, box, plotBox, legend, values: [], cursorT, t: [], vs: paths.map(() => []), start: null, plot: null, loading: true, zoomed: false };
    box.addEventListener('click', () => {
      if (active === index) return;
      active = index;
      for (const c of charts) c.box.classList.toggle('active', c === chart);
      buildPicker();
    });
    remove.addEventListener('click', (e) => {
      e.stopPropagation();
      layout.splice(index, 1);
      active = Math.max(0, Math.min(active, layout.length - 1));
      save();
      rebuild();
    });
    csv.addEventListener('click', (e) => {
      e.stopPropagation();
      const rows = shown(chart);
      const head = ['t_s', ...infos.map((s) => `${s.name}${s.unit ? ` [${s.unit}]` : ''}`)];
      const lines = [head.join(',')];
      for (const [t, vals] of rows) lines.push([t.toFixed(4), ...vals.map((v) => (v === null ? '' : String(v)))].join(','));
      download(`autoplug-plot-${index + 1}.csv`, new Blob([lines.join('\n') + '\n'], { type: 'text/csv' }));
    });
    mcap.addEventListener('click', (e) => {
      e.stopPropagation();
      mcapOf(infos, shown(chart)).then(
        (bytes) => download(`autoplug-plot-${index + 1}.mcap`, new Blob([bytes as BlobPart], { type: 'application/octet-stream' })),
        (err) => ctx.toast(`MCAP export failed: ${err.message ?? err}`, 'error'),
      );
    });
    infos.forEach((s, i) => {
      const value = h('span', { class: 'mono', 'data-testid': 'legend-value' });
      chart.values.push(value);
      const drop = h('button', { class: 'link', title: `remove ${s.name} from this chart` }, '×');
      drop.addEventListener('click', (e) => {
        e.stopPropagation();
        layout[index] = layout[index].filter((p) => p !== s.path);
        save();
        rebuild();
      });
      legend.append(h('span', { class: 'legend-item', title: s.path, 'data-path': s.path },
        h('i', { class: 'swatch', style: `background:${color(i)}` }), h('span', { text: s.name }), value, h('span', { class: 'muted small', text: s.unit }), drop));
    });
    if (paths.length) void fill(chart);
    return chart;
  }

  /** The chart's rows within the x range it shows: [t, values]. */
  function shown(chart: Chart): [number, (number | null)[]][] {
    const min = chart.plot?.scales.x.min ?? -Infinity, max = chart.plot?.scales.x.max ?? Infinity;
    const rows: [number, (number | null)[]][] = [];
    chart.t.forEach((t, i) => {
      if (t >= min && t <= max) rows.push([t, chart.vs.map((v) => v[i])]);
    });
    return rows;
  }

  /** Takes the history of the chart's signals, then follows the stream. */
  async function fill(chart: Chart): Promise<void> {
    chart.loading = true;
    try {
      const history = await get(`/api/history?paths=${chart.paths.map(encodeURIComponent).join(',')}`);
      const first = chart.paths[0];
      const t: number[] = history.signals[first]?.t ?? [];
      chart.t = t.slice();
      chart.vs = chart.paths.map((p) => (history.signals[p]?.v ?? t.map(() => null)).slice());
      chart.start = history.t0;
      chart.box.dataset.start = history.t0 === null ? '' : String(history.t0);
    } catch (e: any) {
      // No history (a gateway without it, or offline): the chart starts now.
      chart.t = [];
      chart.vs = chart.paths.map(() => []);
      chart.box.dataset.historyError = e.message ?? String(e);
    }
    chart.loading = false;
    if (!charts.includes(chart)) return;
    if (!chart.plot) makePlot(chart);
    draw(true);
  }

  function makePlot(chart: Chart): void {
    const infos = chart.paths.map((p) => live.byPath.get(p)!);
    const units = [...new Set(infos.map((s) => s.unit || '–'))];
    const width = Math.max(280, chart.plotBox.clientWidth || chartsEl.clientWidth - 24 || 600);
    const grid = { stroke: 'rgba(128,128,128,.2)' };
    chart.plot = new uPlot(
      {
        width,
        height: 200,
        cursor: { sync: { key: sync.key } },
        scales: { x: { time: false }, ...Object.fromEntries(units.map((u) => [u, { auto: true }])) },
        axes: [
          { label: 'bus time (s)', stroke: 'currentColor', grid },
          ...units.map((u, i) => ({ scale: u, label: u, stroke: 'currentColor', grid: i === 0 ? grid : { show: false }, side: i % 2 === 0 ? 3 : 1 })),
        ],
        series: [
          { label: 't (s)' },
          ...infos.map((s, i) => ({ label: s.name, scale: s.unit || '–', stroke: color(i), width: 1.5, points: { show: false } })),
        ],
        legend: { show: false },
        hooks: {
          setCursor: [(u: uPlot) => showValues(chart, u.cursor.idx ?? null)],
          setSelect: [(u: uPlot) => {
            if (u.select.width > 0) chart.zoomed = true;
          }],
        },
      },
      [chart.t, ...chart.vs] as uPlot.AlignedData,
      chart.plotBox,
    );
    // Double-click zooms out: follow the data again.
    chart.plotBox.addEventListener('dblclick', () => {
      chart.zoomed = false;
      draw(true);
    });
  }

  /** The legend's values: at the cursor, or the latest when the cursor is off the chart. */
  function showValues(chart: Chart, idx: number | null): void {
    chart.paths.forEach((path, i) => {
      const info = live.byPath.get(path)!;
      const v = idx === null ? live.value(path) : chart.vs[i]?.[idx] ?? null;
      setText(chart.values[i], formatValue(info, v));
    });
    setText(chart.cursorT, idx === null ? 'now' : `t = ${num(chart.t[idx], 3)} s`);
  }

  function formatValue(info: SignalInfo, v: number | null): string {
    if (v === null) return 'no data';
    const label = info.labels.find(([raw]) => raw === v)?.[1];
    if (label) return label;
    return Number.isInteger(v) ? String(v) : num(v, Math.abs(v) < 10 ? 3 : 1);
  }

  let lastT = -1;
  let lastDraw = 0;
  function update(): void {
    if (live.catalog.length && charts.length === 0 && layout.length) rebuild();
    if (live.catalog.length && picker.childElementCount === 0) buildPicker();
    if (live.t === lastT) return;
    const gap = lastT >= 0 && live.t - lastT > RESYNC_S;
    const back = live.t < lastT;
    lastT = live.t;
    for (const c of charts) {
      if (c.loading || c.paths.length === 0) continue;
      if (gap || back || c.t.length > MAX_POINTS) {
        // Missed samples (a hidden page), time gone back (a replay started over) or
        // too many points: the history has the session up to now.
        void fill(c);
        continue;
      }
      const last = c.t[c.t.length - 1];
      if (last !== undefined && live.t <= last) continue;
      c.t.push(live.t);
      c.paths.forEach((p, i) => c.vs[i].push(live.value(p)));
    }
    draw(false);
  }

  function draw(now: boolean): void {
    const wall = performance.now();
    if (!now && (paused || wall - lastDraw < 100)) return;
    lastDraw = wall;
    for (const c of charts) {
      if (!c.plot || c.loading) continue;
      c.plot.setData([c.t, ...c.vs] as uPlot.AlignedData, false);
      if (!c.zoomed && c.t.length) {
        const max = c.t[c.t.length - 1];
        const min = windowS === null ? c.t[0] : Math.max(c.t[0], max - windowS);
        c.plot.setScale('x', { min, max: max > min ? max : min + 1 });
      }
      if (c.plot.cursor.idx === null || c.plot.cursor.idx === undefined) showValues(c, null);
      c.box.dataset.points = String(c.t.length);
      c.box.dataset.first = c.t.length ? String(c.t[0]) : '';
    }
  }

  const resize = () => {
    for (const c of charts) c.plot?.setSize({ width: Math.max(280, c.plotBox.clientWidth), height: 200 });
  };
  window.addEventListener('resize', resize);
  return {
    el,
    update,
    destroy() {
      window.removeEventListener('resize', resize);
      for (const c of charts) c.plot?.destroy();
    },
  };
}
