// Frame sets for playback: each bundle (every camera's colour and disparity of one frame set) fetched whole
// and kept until played; a window of frame sets ahead of the one shown is read ahead, a few requests at a
// time, so that playing from a local disk does not wait on the network.

import { decodeBundle } from "./renderer.js";

export class FrameStore {
  constructor(numbers, ahead = 8, parallel = 2) {
    this.numbers = numbers;
    this.ahead = ahead;
    this.parallel = parallel;
    this.ready = new Map();    // index -> decoded bundle
    this.pending = new Map();  // index -> promise
    this.listeners = [];
  }

  get(index) { return this.ready.get(index); }

  // The bundle of frame set `index`, fetched when it is not yet here.
  load(index) {
    if (this.ready.has(index)) return Promise.resolve(this.ready.get(index));
    if (!this.pending.has(index)) {
      const n = this.numbers[index];
      const p = fetch(`/api/frame/${n}.bin`).then((res) => {
        if (!res.ok) throw new Error(`frame set ${n}: HTTP ${res.status}`);
        return res.arrayBuffer();
      }).then((buf) => {
        const bundle = decodeBundle(buf);
        if (bundle.header.number !== n) throw new Error(`asked for frame set ${n}, got ${bundle.header.number}`);
        this.ready.set(index, bundle);
        this.pending.delete(index);
        this.listeners.forEach((f) => f(index));
        return bundle;
      });
      this.pending.set(index, p);
    }
    return this.pending.get(index);
  }

  // Read ahead of `index` (wrapping when looping) and forget what is well behind it.
  around(index, loop) {
    const count = this.numbers.length;
    for (const i of [...this.ready.keys()]) {
      const behind = (index - i + count) % count;
      if (behind > 2 && behind < count - this.ahead) this.ready.delete(i);
    }
    for (let k = 0; k <= this.ahead && this.pending.size < this.parallel; k++) {
      let i = index + k;
      if (i >= count) { if (!loop) break; i %= count; }
      if (!this.ready.has(i) && !this.pending.has(i)) this.load(i).catch((e) => this.listeners.forEach((f) => f(i, e)));
    }
  }
}
