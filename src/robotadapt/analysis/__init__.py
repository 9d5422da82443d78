"""Numbers about runs and designs (layer `analysis`): metrics (:mod:`.metrics`), monitors against the stability proofs
(:mod:`.monitors`), persistency of excitation (:mod:`.excitation`) and the gain conditions of §7.2 (:mod:`.gains`)."""
