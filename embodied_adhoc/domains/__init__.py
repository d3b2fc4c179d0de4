"""Abstract task models built from each domain's rules (the HOTSPOT lab, foraging, pursuit, the chapter-5 domains):
rules -> model libraries sharing one state indexing (docs/hotspot.md).

Where this layer sits and what it may import: docs/layout.md."""
