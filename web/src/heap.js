// A binary heap on (err, node) pairs: std::priority_queue's role in mtrender/extract.cpp.
export class Heap {
  /** @param {boolean} largestFirst */
  constructor(largestFirst) {
    this.err = [];
    this.node = [];
    this.sign = largestFirst ? 1 : -1;
  }
  get size() { return this.err.length; }
  empty() { return this.err.length === 0; }
  topErr() { return this.err[0]; }
  topNode() { return this.node[0]; }
  // a before b
  _before(i, j) { return this.sign * (this.err[i] - this.err[j]) > 0; }
  _swap(i, j) {
    const e = this.err[i]; this.err[i] = this.err[j]; this.err[j] = e;
    const n = this.node[i]; this.node[i] = this.node[j]; this.node[j] = n;
  }
  push(err, node) {
    this.err.push(err);
    this.node.push(node);
    let i = this.err.length - 1;
    while (i > 0) {
      const p = (i - 1) >> 1;
      if (!this._before(i, p)) break;
      this._swap(i, p);
      i = p;
    }
  }
  pop() {
    const n = this.err.length - 1;
    this._swap(0, n);
    this.err.pop();
    this.node.pop();
    let i = 0;
    for (;;) {
      const l = 2 * i + 1, r = l + 1;
      let b = i;
      if (l < n && this._before(l, b)) b = l;
      if (r < n && this._before(r, b)) b = r;
      if (b === i) break;
      this._swap(i, b);
      i = b;
    }
  }
}
