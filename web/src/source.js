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

export class HttpSource {
  /** @param {string} url */
  constructor(url) {
    this.path = url;
    this.url = url;
    this.size = 0;
    this.bytesFetched = 0;
    this.requests = 0;
  }
  /** Reads the last `tail` bytes (a suffix range) and learns the file size from Content-Range. */
  async openTail(tail) {
    const r = await this._fetch(`bytes=-${tail}`);
    const cr = r.headers.get('Content-Range') || '';
    const m = /\/(\d+)\s*$/.exec(cr);
    if (!m) throw new Error(`${this.url}: no file size in the Content-Range header of a 206 answer ("${cr}")`);
    this.size = Number(m[1]);
    return r.arrayBuffer().then((b) => { this.bytesFetched += b.byteLength; return b; });
  }
  async _fetch(range) {
    let r;
    try {
      r = await fetch(this.url, { headers: { Range: range } });
    } catch (e) {
      throw new Error(`${this.url}: cannot fetch: ${e.message}`);
    }
    ++this.requests;
    if (r.status === 200) {
      // Do not download a whole multi-gigabyte file we did not ask for.
      try { r.body && r.body.cancel(); } catch (_) { /* already closed */ }
      throw new NoRangeError(this.url, r.status);
    }
    if (r.status !== 206) throw new Error(`${this.url}: HTTP ${r.status} ${r.statusText} for range ${range}`);
    return r;
  }
  /** Bytes [begin, end). */
  async read(begin, end) {
    if (end <= begin) return new ArrayBuffer(0);
    const r = await this._fetch(`bytes=${begin}-${end - 1}`);
    const b = await r.arrayBuffer();
    if (b.byteLength !== end - begin)
      throw new Error(`${this.url}: asked for bytes ${begin}-${end - 1}, got ${b.byteLength} bytes`);
    this.bytesFetched += b.byteLength;
    return b;
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
