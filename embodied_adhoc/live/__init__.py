"""Real-time toxic-waste lab: asynchronous decisions (``live.realtime``), human drivers (``live.humans``), the
real-time episode (``live.episode``) and the browser live mode (``live.server``). See docs/live.md."""
