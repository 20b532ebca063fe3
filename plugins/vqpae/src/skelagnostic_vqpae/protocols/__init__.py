"""VQ-PAE's evaluation protocols and fit summary.

They use the model (:mod:`skelagnostic_vqpae.training`), its embeddings
(:mod:`skelagnostic_vqpae.embed`) and its transfer (:mod:`skelagnostic_vqpae.transfer`),
never the other way round (``tests/test_layering.py``); only the public aligner
(:mod:`skelagnostic_vqpae.aligner`) and the plugin's wiring sit above them. Modules:
:mod:`~skelagnostic_vqpae.protocols.manifold` (``vqpae.manifold``),
:mod:`~skelagnostic_vqpae.protocols.transfer` (``vqpae.transfer``),
:mod:`~skelagnostic_vqpae.protocols.tables` (the paper's Tables 1 and 2),
:mod:`~skelagnostic_vqpae.protocols.rhythm` (foot rhythm figures),
:mod:`~skelagnostic_vqpae.protocols.procedural` (held-out procedural gaits) and
:mod:`~skelagnostic_vqpae.protocols.summary` (what a fit writes into its run directory).
"""
