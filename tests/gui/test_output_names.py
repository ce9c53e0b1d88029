"""Output layers are named after the stack they came from (issue 14, item 6): with two
stacks open napari numbered them (``segments [1]``), which said nothing of their source."""

from __future__ import annotations

from _gui_helpers import run_and_wait

from napari_polarseg.widgets._layers import TAG, own_layers

FAST = {"window": 10, "degree": 4, "n_segments": 3}


def test_outputs_of_two_stacks_carry_their_stack_names(viewer, open_sample, add_widget, qtbot):
    leaves, fruit = open_sample("leaves"), open_sample("fruit")
    pol = add_widget("Polarisation image")
    seg = add_widget("Segment by material")
    seg.set_params(**FAST)
    for stack in (leaves, fruit):
        for widget in (pol, seg):
            widget.stack_layer.value = stack
            run_and_wait(qtbot, widget)
    names = {layer.name for layer in viewer.layers}
    for stack in ("leaves", "fruit"):
        for role in ("segments", "reconstruction error", "Î intensity", "ρ degree of polarisation"):
            assert f"{role} ({stack})" in names
    assert not any("[" in name for name in names)  # nothing numbered by napari
    for stack in (leaves, fruit):
        outputs = own_layers(viewer, stack)
        assert len(outputs) >= 6
        assert all(layer.name.endswith(f" ({stack.name})") for layer in outputs)
        # lookups go through the tag, not the name
        assert seg.output("segments", stack) is viewer.layers[f"segments ({stack.name})"]
        assert seg.output("segments", stack).metadata[TAG]["role"] == "segments"
    # a rerun of one stack replaces its layers in place and leaves the other's alone
    n_layers = len(viewer.layers)
    seg.stack_layer.value = leaves
    seg.n_segments.value = 2
    before = seg.output("segments", fruit).data.copy()
    run_and_wait(qtbot, seg)
    assert len(viewer.layers) == n_layers
    assert set(viewer.layers["segments (leaves)"].data.ravel()) == {1, 2}
    assert (viewer.layers["segments (fruit)"].data == before).all()
