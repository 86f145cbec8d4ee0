// Byte sources for an MT file: HTTP range requests (the browser), or a local file (Node, for the
// tests). A source has `path`, `size` and `read(begin, end)` -> Promise<ArrayBuffer>.

/** The server ignored the Range header (200 instead of 206): this file cannot be streamed. */
export class NoRangeError extends Error {
  constructor(url, status) {
    super(`${url}: the server answered ${status} to a range request instead of 206 Partial Content: ` +
      'it does not serve byte ranges, and an MT file is streamed by ranges (patches are read on demand). ' +
      'Serve the file with a server that supports Range requests (mtserve, nginx, Apache, any static ' +
      'server with range support; see web/README.md).');
    this.name = 'NoRangeError';
    this.status = status;
  }
}

/** How much of a file's end the first read takes (HttpSource `tailBytes`): the footer, the index
 * section before it (3.4 MiB for a 53 M-triangle build) and the payloads just before that, which
 * are the coarsest levels' (mtbuild writes the levels bottom up), in one request. */
export const kDefaultTailBytes = 4 << 20;

export class HttpSource {
  /**
   * @param {string} url
   * @param {{tailBytes?:number, early?:{head:Promise<Response>, tail:Promise<Response>}}} [opt]
   * `tailBytes`: the first read's suffix (kDefaultTailBytes); its bytes are kept, and reads that lie
   * in them are answered from memory, until release(). `early`: the same two requests started by
   * the page before its modules loaded (viewer.html: `HttpSource.startEarly`'s inline copy): the
   * header ([0, 256)) and the suffix of `early.tailBytes`.
   */
  constructor(url, opt = {}) {
    this.path = url;
    this.url = url;
    this.size = 0;
    this.bytesFetched = 0;
    this.requests = 0;
    this.tailBytes = opt.tailBytes || kDefaultTailBytes;
    this.early = opt.early || null;
    this.kept = null;  // {begin, buf}: the file's last bytes, read by openTail
    this.keptReads = 0;  // reads answered from them
  }
  /**
   * The page's early requests for `url` (viewer.html makes the same two at once from an inline
   * script, before three.js and the modules load): the header and the file's last `tailBytes`.
   */
  static startEarly(url, tailBytes = kDefaultTailBytes, headerBytes = 256) {
    // A partial answer's body is read at once (`mtBody`), not when the opening gets to it.
    const get = (range) => fetch(url, { headers: { Range: range } }).then((r) => {
      if (r.status === 206) (r.mtBody = r.arrayBuffer()).catch(() => {});
      return r;
    });
    const e = { head: get(`bytes=0-${headerBytes - 1}`), tail: get(`bytes=-${tailBytes}`), tailBytes };
    e.head.catch(() => {});  // reported when the opening awaits them
    e.tail.catch(() => {});
    return e;
  }
  /**
   * Reads the last `tail` bytes and learns the file size from Content-Range. The read asks for the
   * last max(tail, tailBytes) bytes (or takes the page's early request): they are kept for read().
   */
  async openTail(tail) {
    let r, range;
    if (this.early) {
      range = `bytes=-${this.early.tailBytes}`;
      r = this._check(await this._await(this.early.tail), range);
    } else {
      range = `bytes=-${Math.max(tail, this.tailBytes)}`;
      r = await this._fetch(range);
    }
    const cr = r.headers.get('Content-Range') || '';
    const m = /(\d+)-(\d+)\/(\d+)\s*$/.exec(cr);
    if (!m) throw new Error(`${this.url}: no file size in the Content-Range header of a 206 answer ("${cr}")`);
    this.size = Number(m[3]);
    const buf = await (r.mtBody || r.arrayBuffer());
    if (buf.byteLength !== Number(m[2]) - Number(m[1]) + 1 || Number(m[2]) !== this.size - 1 || buf.byteLength < Math.min(tail, this.size))
      throw new Error(`${this.url}: asked for ${range}, got ${buf.byteLength} bytes (Content-Range "${cr}")`);
    this.bytesFetched += buf.byteLength;
    this.kept = { begin: this.size - buf.byteLength, buf };
    return buf.slice(Math.max(0, buf.byteLength - tail));
  }
  /** Forgets the kept tail (its reads are served; later reads go to the server). */
  release() { this.kept = null; }
  async _await(p) {
    try {
      return await p;
    } catch (e) {
      throw new Error(`${this.url}: cannot fetch: ${e.message}`);
    }
  }
  _check(r, range) {
    ++this.requests;
    if (r.status === 200) {
      // Do not download a whole multi-gigabyte file we did not ask for.
      try { r.body && r.body.cancel(); } catch (_) { /* already closed */ }
      throw new NoRangeError(this.url, r.status);
    }
    if (r.status !== 206) throw new Error(`${this.url}: HTTP ${r.status} ${r.statusText} for range ${range}`);
    return r;
  }
  async _fetch(range) {
    return this._check(await this._await(fetch(this.url, { headers: { Range: range } })), range);
  }
  /** Bytes [begin, end). */
  async read(begin, end) {
    if (end <= begin) return new ArrayBuffer(0);
    const k = this.kept;
    if (k && begin >= k.begin) {
      ++this.keptReads;
      if (begin === 0 && this.early && this.early.head) {
        // The file is shorter than the tail read: the page's early header request is not needed.
        const head = this.early.head;
        this.early.head = null;
        head.then((r) => (r.mtBody || !r.body ? null : r.body.cancel())).catch(() => {});
      }
      return k.buf.slice(begin - k.begin, end - k.begin);
    }
    let r;
    const range = `bytes=${begin}-${end - 1}`;
    if (this.early && this.early.head && begin === 0) {
      // The page's early header request, once (the opening's header read).
      const head = this.early.head;
      this.early.head = null;
      r = this._check(await this._await(head), range);
    }
    // A read that ends in the kept tail asks only for the bytes before it.
    const to = k && end > k.begin ? k.begin : end;
    if (!r) r = await this._fetch(`bytes=${begin}-${to - 1}`);
    let b = await (r.mtBody || r.arrayBuffer());
    if (b.byteLength > to - begin) b = b.slice(0, to - begin);  // the early header's request, asked before `end` was known
    if (b.byteLength !== to - begin)
      throw new Error(`${this.url}: asked for bytes ${begin}-${to - 1}, got ${b.byteLength} bytes`);
    this.bytesFetched += b.byteLength;
    if (to === end) return b;
    ++this.keptReads;
    const all = new Uint8Array(end - begin);
    all.set(new Uint8Array(b), 0);
    all.set(new Uint8Array(k.buf, 0, end - to), to - begin);
    return all.buffer;
  }
}

/** A local file (Node only): the same interface, for the tests and the cut comparison. */
export class FileSource {
  constructor(path, fsModule) {
    this.path = path;
    this.fs = fsModule;
    this.fd = fsModule.openSync(path, 'r');
    this.size = fsModule.fstatSync(this.fd).size;
    this.bytesFetched = 0;
    this.requests = 0;
  }
  async openTail(tail) { return this.read(Math.max(0, this.size - tail), this.size); }
  async read(begin, end) {
    const b = Buffer.alloc(end - begin);
    this.fs.readSync(this.fd, b, 0, end - begin, begin);
    this.bytesFetched += end - begin;
    ++this.requests;
    return b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength);
  }
  close() { this.fs.closeSync(this.fd); }
}
