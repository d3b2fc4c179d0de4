"""Recording of episodes: mp4 video with an overlay, rerun ``.rrd`` logs, ``metrics.json``; recorders never import
``experiments`` (docs/recording.md).

Where this layer sits and what it may import: docs/layout.md."""
