"""Offline speech for the lab's "locate human" query: synthesis (espeak-ng), recognition (pocketsphinx with a
grammar and an MLLR adaptation), place parsing, speech channels and the measured confusion matrix (docs/speech.md).

Where this layer sits and what it may import: docs/layout.md."""
