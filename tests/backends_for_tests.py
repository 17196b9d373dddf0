"""Backends used only by the comparison tests: a correct second opinion, and broken ones."""
from dataclasses import replace

from mdgran.backends.reference import ReferenceBackend
from mdgran.model.contact import ContactLaw


class TightReference(ReferenceBackend):
    """The reference at 1/1000 of the scene's tolerance: a correct second backend."""

    name = "tight-reference"

    def __init__(self, scene, **options):
        tol = float(scene.data["run"]["tolerance"]) * 1e-3
        super().__init__(scene, tolerance=tol, **options)


class FlippedDamping(TightReference):
    """Damping with the wrong sign: it pumps energy in."""

    name = "flipped-damping"

    def __init__(self, scene, **options):
        super().__init__(scene, **options)
        self.model = replace(self.model, damping=-self.model.damping)


class WrongSnapOff(TightReference):
    """Snap-off at the force maximum where the scene asks for the displacement rule."""

    name = "wrong-snap-off"

    def __init__(self, scene, **options):
        super().__init__(scene, **options)
        law = self.model.law
        self.model = replace(self.model, law=ContactLaw(law.kind, law.fc, "force"))
        self.delta_off = self.model.law.delta_off


class LedgerDefect(ReferenceBackend):
    """The reference with a bookkeeping defect: ``D_hysteresis`` gains ``DEFECT * E_imp``
    spread linearly over the run, so the ledger error ends at ``DEFECT`` (of E_imp)."""

    name = "ledger-defect"
    DEFECT = 1e-5

    def frames(self, resume=None):
        duration = float(self.scene.data["run"]["duration"])
        extra = self.DEFECT * (self.scene.impulse_energy or 1.0)
        for fr in super().frames(resume):
            yield replace(fr, dissipated_hysteresis=fr.dissipated_hysteresis
                          + extra * fr.time / duration)
