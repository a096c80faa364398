// A round gauge in SVG: a 240° arc with ticks, a filled arc up to the value, a red zone and
// the figure in the middle, as a driver reads a speedometer at a glance.

const NS = 'http://www.w3.org/2000/svg';
const START = 150; // degrees, clockwise from the x axis
const SWEEP = 240;

function svg<K extends keyof SVGElementTagNameMap>(tag: K, attrs: Record<string, string | number>): SVGElementTagNameMap[K] {
  const el = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, String(v));
  return el;
}

function point(angle: number, r: number): [number, number] {
  const a = (angle * Math.PI) / 180;
  return [100 + r * Math.cos(a), 100 + r * Math.sin(a)];
}

function arc(from: number, to: number, r: number): string {
  const [x1, y1] = point(from, r);
  const [x2, y2] = point(to, r);
  const large = to - from > 180 ? 1 : 0;
  return `M ${x1.toFixed(2)} ${y1.toFixed(2)} A ${r} ${r} 0 ${large} 1 ${x2.toFixed(2)} ${y2.toFixed(2)}`;
}

export class Gauge {
  readonly el: SVGSVGElement;
  private fill: SVGPathElement;
  private figure: SVGTextElement;
  private lastText = '';

  constructor(
    readonly label: string,
    readonly unit: string,
    readonly max: number,
    readonly step: number,
    readonly redFrom: number | null = null,
    readonly digits = 0,
    readonly labelEvery = 1,
  ) {
    this.el = svg('svg', { viewBox: '0 0 200 170', class: 'gauge', role: 'img', 'aria-label': label });
    this.el.append(svg('path', { d: arc(START, START + SWEEP, 80), class: 'gauge-track' }));
    if (redFrom !== null) {
      this.el.append(svg('path', { d: arc(this.angle(redFrom), START + SWEEP, 80), class: 'gauge-red' }));
    }
    this.fill = svg('path', { d: '', class: 'gauge-fill' });
    this.el.append(this.fill);
    for (let i = 0, v = 0; v <= max + 1e-9; i++, v += step) {
      const a = this.angle(v);
      const [x1, y1] = point(a, 66);
      const [x2, y2] = point(a, 72);
      this.el.append(svg('line', { x1, y1, x2, y2, class: 'gauge-tick' }));
      if (i % labelEvery !== 0) continue;
      const [tx, ty] = point(a, 55);
      const t = svg('text', { x: tx, y: ty + 3, class: 'gauge-scale', 'text-anchor': 'middle' });
      t.textContent = max >= 1000 ? String(v / 1000) : String(v);
      this.el.append(t);
    }
    this.figure = svg('text', { x: 100, y: 112, class: 'gauge-figure', 'text-anchor': 'middle' });
    this.el.append(this.figure);
    const unitText = svg('text', { x: 100, y: 132, class: 'gauge-unit', 'text-anchor': 'middle' });
    unitText.textContent = unit;
    this.el.append(unitText);
    if (max >= 1000) {
      // The figure is the whole value; only the scale's numbers are in thousands.
      const factor = svg('text', { x: 100, y: 80, class: 'gauge-scale', 'text-anchor': 'middle' });
      factor.textContent = 'scale × 1000';
      this.el.append(factor);
    }
    const labelText = svg('text', { x: 100, y: 160, class: 'gauge-label', 'text-anchor': 'middle' });
    labelText.textContent = label;
    this.el.append(labelText);
    this.set(null);
  }

  private angle(v: number): number {
    return START + (SWEEP * Math.min(Math.max(v, 0), this.max)) / this.max;
  }

  set(value: number | null): void {
    const text = value === null ? '–' : value.toFixed(this.digits);
    if (text === this.lastText) return;
    this.lastText = text;
    this.figure.textContent = text;
    this.el.dataset.value = value === null ? '' : text;
    const to = value === null ? START : this.angle(value);
    this.fill.setAttribute('d', to - START > 0.5 ? arc(START, to, 80) : '');
    this.el.classList.toggle('in-red', value !== null && this.redFrom !== null && value >= this.redFrom);
  }
}
