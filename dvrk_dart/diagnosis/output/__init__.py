"""The answer: words, the page, the printout, where the gap is."""
