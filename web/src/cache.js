// The byte-capped patch cache of the browser: decoded patches (and the three.js geometry made from
// them) by patch id, with the states of mtrender/patch_cache.h (absent, loading, ready, bad), pins
// for the patches of the cut, and eviction of the least recently wanted unpinned patch when a load
// needs room. The cap counts every patch's decoded size bound (Scene::decodedBytesBound: 20 bytes a
// vertex, 12 a triangle; a textured patch's split vertices and RGBA8 atlas, texture.js) from the
// moment its load is reserved, then, once it is decoded, the bytes it actually takes (its arrays
// and atlas), so the bytes held never exceed the cap; a load that cannot find room is refused
// (counted in givenUp) and asked for again later.

export class PatchCache {
  /**
   * @param {number} capBytes
   * @param {(id:number, entry:object)=>void} onEvict called when a ready patch's content goes
   */
  constructor(capBytes, onEvict) {
    this.capBytes = capBytes;
    this.usedBytes = 0;
    this.peakBytes = 0;
    this.entries = new Map();  // id -> {state, bytes, pins, last, data}
    this.onEvict = onEvict || (() => {});
    this.textureBytes = 0;  // of usedBytes: the ready patches' atlases (RGBA8)
    this.evictions = 0;
    this.givenUp = 0;
    this.frame = 0;
    this.generation = 0;  // counts patches ready, bad, evicted, cancelled or refused room (ExtractRender.stillRepeats)
  }
  state(id) {
    const e = this.entries.get(id);
    return e ? e.state : 'absent';
  }
  isBad(id) { return this.state(id) === 'bad'; }
  get(id) { return this.entries.get(id); }
  /** Room for a load of `bytes`; evicts unpinned ready patches, the least recently wanted first. */
  reserve(id, bytes) {
    if (this.entries.has(id)) return false;
    if (this.usedBytes + bytes > this.capBytes) {
      const victims = [];
      for (const [vid, e] of this.entries) if (e.state === 'ready' && e.pins === 0 && e.last < this.frame) victims.push([e.last, vid]);
      victims.sort((a, b) => a[0] - b[0]);
      for (const [, vid] of victims) {
        if (this.usedBytes + bytes <= this.capBytes) break;
        this.evict(vid);
      }
      if (this.usedBytes + bytes > this.capBytes) {
        ++this.givenUp;
        ++this.generation;  // asked for again later: not a state to skip an update on
        return false;
      }
    }
    this.entries.set(id, { state: 'loading', bytes, pins: 0, last: this.frame, data: null });
    this.usedBytes += bytes;
    this.peakBytes = Math.max(this.peakBytes, this.usedBytes);
    return true;
  }
  evict(id) {
    const e = this.entries.get(id);
    if (!e) return;
    if (e.state === 'ready') this.onEvict(id, e), ++this.generation;
    this.usedBytes -= e.bytes;
    this.textureBytes -= e.textureBytes || 0;
    this.entries.delete(id);
    ++this.evictions;
  }
  /**
   * A reserved load arrived. `bytes`: what it actually takes (its arrays and, textured, its RGBA8
   * atlas), at most the reserved bound; the entry holds that from now on. `textureBytes`: the
   * atlas's share of it.
   */
  commit(id, data, bytes, textureBytes = 0) {
    const e = this.entries.get(id);
    if (!e) return;
    e.state = 'ready';
    e.data = data;
    ++this.generation;
    e.textureBytes = textureBytes;
    this.textureBytes += textureBytes;
    if (bytes !== undefined && bytes <= e.bytes) {
      this.usedBytes -= e.bytes - bytes;
      e.bytes = bytes;
    }
  }
  /** A reserved load failed for good (damaged payload): keeps the id as bad, frees its bytes. */
  markBad(id) {
    const e = this.entries.get(id) || { pins: 0, last: 0 };
    if (e.bytes) this.usedBytes -= e.bytes;
    this.entries.set(id, { state: 'bad', bytes: 0, pins: 0, last: e.last, data: null });
    ++this.generation;
  }
  /** A reserved load failed for now (network): forget it. */
  cancel(id) {
    const e = this.entries.get(id);
    if (!e || e.state !== 'loading') return;
    this.usedBytes -= e.bytes;
    this.entries.delete(id);
    ++this.generation;
  }
  /** Pins every patch of `ids` when all are ready (a move is applied atomically); false otherwise. */
  pinAll(ids) {
    for (const id of ids) if (this.state(id) !== 'ready') return false;
    for (const id of ids) {
      const e = this.entries.get(id);
      ++e.pins;
      e.last = this.frame;
    }
    return true;
  }
  unpinAll(ids) {
    for (const id of ids) {
      const e = this.entries.get(id);
      if (e && e.pins > 0) --e.pins;
    }
  }
  touch(ids, frame) {
    this.frame = frame;
    for (const id of ids) {
      const e = this.entries.get(id);
      if (e) e.last = frame;
    }
  }
}
