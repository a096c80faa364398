// Plots: live time series of any signals, several at once (one chart each, cursors in
// step), with pause and zoom (drag across a chart; double-click to zoom out).
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';
import type { Ctx, View } from '../view';
import { h } from '../util';

/** Seconds of bus time kept per signal. */
const WINDOW_S = 120;
const DEFAULT = ['Vehicle.Speed', 'Vehicle.Powertrain.CombustionEngine.Speed'];
const KEY = 'autoplug-plots';

interface Series {
  path: string;
  t: number[];
  v: (number | null)[];
  plot: uPlot | null;
  box: HTMLElement;
}

function color(i: number): string {
  const hues = [205, 25, 140, 280, 50, 330, 175, 0];
  return `hsl(${hues[i % hues.length]} 75% 50%)`;
}

export function plotsView(ctx: Ctx): View {
  const { live } = ctx;
  let chosen: string[] = (() => {
    try {
      const saved = JSON.parse(localStorage.getItem(KEY) ?? 'null');
      return Array.isArray(saved) && saved.length ? saved : DEFAULT;
    } catch {
      return DEFAULT;
    }
  })();
  let paused = false;
  const series = new Map<string, Series>();
  const charts = h('div', { class: 'charts' });
  const picker = h('div', { class: 'picker' });
  const filter = h('input', { type: 'search', placeholder: 'filter signals', class: 'filter', 'aria-label': 'filter signals' });
  const pause = h('button', { class: 'btn', 'data-testid': 'pause' }, 'Pause');
  pause.addEventListener('click', () => {
    paused = !pause.classList.toggle('active') ? false : true;
    pause.textContent = paused ? 'Resume' : 'Pause';
  });
  const el = h('section', { class: 'plots' },
    h('aside', { class: 'card side' }, h('h3', { text: 'Signals' }), filter, picker),
    h('div', { class: 'main-col' }, h('div', { class: 'toolbar' }, pause, h('span', { class: 'muted small', text: 'Drag across a chart to zoom, double-click to zoom out.' })), charts),
  );
  const sync = uPlot.sync('plots');

  function buildPicker(): void {
    picker.replaceChildren();
    const f = filter.value.toLowerCase();
    for (const s of live.catalog) {
      if (f && !s.path.toLowerCase().includes(f) && !s.name.toLowerCase().includes(f)) continue;
      const box = h('input', { type: 'checkbox', checked: chosen.includes(s.path), 'data-path': s.path });
      box.addEventListener('change', () => {
        chosen = box.checked ? [...chosen, s.path] : chosen.filter((p) => p !== s.path);
        localStorage.setItem(KEY, JSON.stringify(chosen));
        layout();
      });
      picker.append(h('label', { class: 'pick', title: s.path }, box, h('span', { text: s.name }), h('span', { class: 'muted small', text: s.unit })));
    }
  }
  filter.addEventListener('input', buildPicker);

  function layout(): void {
    for (const [path, s] of series) {
      if (!chosen.includes(path)) {
        s.plot?.destroy();
        s.box.remove();
        series.delete(path);
      }
    }
    chosen.forEach((path, i) => {
      if (series.has(path) || !live.byPath.has(path)) return;
      const box = h('div', { class: 'card chart', 'data-testid': `chart-${path}` });
      charts.append(box);
      series.set(path, { path, t: [], v: [], plot: null, box });
      makePlot(series.get(path)!, i);
    });
  }

  function makePlot(s: Series, i: number): void {
    const info = live.byPath.get(s.path)!;
    const width = Math.max(280, s.box.clientWidth - 24 || charts.clientWidth - 24 || 600);
    s.plot = new uPlot(
      {
        title: `${info.name} (${info.unit || '–'})`,
        width,
        height: 180,
        cursor: { sync: { key: sync.key } },
        scales: { x: { time: false } },
        axes: [
          { label: 'bus time (s)', stroke: 'currentColor', grid: { stroke: 'rgba(128,128,128,.2)' } },
          { label: info.unit, stroke: 'currentColor', grid: { stroke: 'rgba(128,128,128,.2)' } },
        ],
        series: [{ label: 't (s)' }, { label: info.path, stroke: color(i), width: 1.5, points: { show: false } }],
        legend: { show: true },
      },
      [s.t, s.v],
      s.box,
    );
  }

  let lastT = -1;
  let lastDraw = 0;
  function update(): void {
    if (live.catalog.length && picker.childElementCount === 0) buildPicker();
    if (series.size === 0 && live.catalog.length) layout();
    if (live.t === lastT) return;
    lastT = live.t;
    for (const s of series.values()) {
      s.t.push(live.t);
      s.v.push(live.value(s.path));
      const cut = s.t.findIndex((t) => t >= live.t - WINDOW_S);
      if (cut > 0) {
        s.t.splice(0, cut);
        s.v.splice(0, cut);
      }
      if (cut === -1) {
        s.t.length = 0;
        s.v.length = 0;
      }
    }
    const now = performance.now();
    if (paused || now - lastDraw < 100) return;
    lastDraw = now;
    for (const s of series.values()) {
      // Keep a zoom the user chose: only follow the data when fully zoomed out.
      const zoomed = s.plot && s.plot.scales.x.min !== undefined && s.plot.select.width > 0;
      s.plot?.setData([s.t, s.v], !zoomed);
    }
  }

  const resize = () => {
    for (const s of series.values()) s.plot?.setSize({ width: Math.max(280, s.box.clientWidth - 24), height: 180 });
  };
  window.addEventListener('resize', resize);
  return {
    el,
    update,
    destroy() {
      window.removeEventListener('resize', resize);
      for (const s of series.values()) s.plot?.destroy();
    },
  };
}
