"""``python -m bench.conformance``: run the conformance suite against PEPit's examples."""

from bench.conformance import main

main()
