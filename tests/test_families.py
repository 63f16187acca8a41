"""The family table (rigsim.families) against what each layer dispatches on."""

import pytest

from rigsim.cli import build_parser
from rigsim.dataset.generators import GENERATORS, generator_for_rig
from rigsim.families import FAMILIES, family_of
from rigsim.rig.load import RIG_MODELS, default_rigs, load_any_rig, resolve_rig_path
from rigsim.view.api import builder_for


def test_every_seed_document_has_one_family_and_schema():
    seeds = [s for f in FAMILIES for s in f.seeds]
    assert len(seeds) == len(set(seeds))
    assert set(seeds) == set(RIG_MODELS)
    for f in FAMILIES:
        for s in f.seeds:
            assert RIG_MODELS[s] is f.rig_class


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.name)
def test_family_pieces_agree_across_layers(fam):
    rig = load_any_rig(fam.default_rig)
    assert family_of(rig) is fam
    assert rig.seed_document in fam.seeds
    assert callable(builder_for(rig))
    text = resolve_rig_path(fam.default_rig).read_text()
    assert GENERATORS[generator_for_rig(text)] in fam.generators
    for g in fam.generators:
        assert GENERATORS[g.kind] is g and set(g.seeds) <= set(fam.seeds)


def test_every_default_rig_belongs_to_a_family():
    for p in default_rigs():
        assert family_of(load_any_rig(p)).name in {f.name for f in FAMILIES}


def test_every_family_registers_a_procedure_command():
    p = build_parser()
    run = next(a for a in p._subparsers._group_actions[0].choices["run"]._actions
               if a.__class__.__name__ == "_SubParsersAction")
    assert {"cube-mirror", "boresight", "star-calibration"} <= set(run.choices)


def test_family_of_refuses_a_foreign_object():
    with pytest.raises(TypeError, match="not the rig of any family"):
        family_of(object())
