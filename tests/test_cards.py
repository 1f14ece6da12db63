"""Task-card parsing: valid cards load; every bad field names its file and field."""

from __future__ import annotations

import pytest

import grail_bench
from grail_bench.task import registration
from grail_bench.task.cards import CardError, load_cards, parse_card

GOOD = """
domain = "minigrid"
[[task]]
id = "GRAIL/Test-v0"
regime = "suboptimal"
goals = [[7, 1], [7, 7]]
params = { turn_prob = 0.5 }
"""


def test_good_card_merges_defaults():
    (card,) = parse_card(GOOD, "good.toml")
    assert card.id == "GRAIL/Test-v0"
    assert card.params == {"route_choice": "uniform", "turn_prob": 0.5, "turn_pattern": "left-right"}
    assert card.env_params["max_steps"] == 60
    assert card.source == "good.toml"
    assert card.protocol == "subset"
    assert (card.n_demos, card.n_train) == (10, 7)
    assert card.observability == (0.1, 0.2, 0.3)


def test_shipped_cards_load():
    ids = [c.id for c in load_cards()]
    assert len(ids) == len(set(ids))
    assert "GRAIL/MiniGrid-Biased-v0" in ids


@pytest.mark.parametrize(
    "text, where",
    [
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "lazy"\ngoals = [[7,1],[7,7]]', "task[0].regime"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\nprotocol = "middle"',
         "task[0].protocol"),
        ('domain = "minigrid"\n[[task]]\nid = "bad id"\nregime = "optimal"\ngoals = [[7,1],[7,7]]', "task[0].id"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1]]', "task[0].goals"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1,2],[7,7,2]]', "task[0].goals"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,1]]', "task[0].goals"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\ncolour = 3', "task[0].colour"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\nparams = { turn_prob = 0.1 }', "task[0].params.turn_prob"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\nenv = { speed = 2 }', "task[0].env.speed"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\nenv = { max_steps = -1 }',
         "task[0].env.max_steps"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\nenv = { max_steps = 5.5 }',
         "task[0].env.max_steps"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\ndemos = 3', "task[0].demos"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\nn_train = 10', "task[0].n_train"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\nn_demos = 0', "task[0].n_demos"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\nobservability = [0, 0.5]', "task[0].observability"),
        ('domain = "chess"\n[[task]]\nid = "GRAIL/T-v0"', "domain"),
        ('domain = "minigrid"', "task"),
        ('domain = "minigrid"\ncolour = 1\n[[task]]\nid = "GRAIL/T-v0"', "colour"),
        # Regime parameters are checked when the card is parsed, not when demonstrations are generated.
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "biased"\ngoals = [[7,1],[7,7]]\n'
         'params = { routes = ["NE"] }', "task[0].params"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "biased"\ngoals = [[7,1],[7,7]]\n'
         'params = { routes = ["NE", "XY"] }', "task[0].params"),
        ('domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "suboptimal"\ngoals = [[7,1],[7,7]]\n'
         'params = { turn_prob = 1.5 }', "task[0].params"),
        ('domain = "panda_reach"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[0,0,0.1],[3,0,0.1]]',
         "task[0].goals"),  # the domain's own check of a goal names the goals
    ],
)
def test_bad_field_names_file_and_field(text, where):
    with pytest.raises(CardError) as info:
        parse_card(text, "tasks/bad.toml")
    assert str(info.value).startswith(f"tasks/bad.toml: {where}:")
    assert "\n" not in str(info.value)


def test_invalid_toml_names_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("domain = \n")
    with pytest.raises(CardError, match="broken.toml: invalid TOML"):
        load_cards([path])


ONE = 'domain = "minigrid"\n[[task]]\nid = "GRAIL/T-v0"\nregime = "optimal"\ngoals = [[7,1],[7,7]]\n'


def test_duplicate_id_in_one_card_names_the_file():
    with pytest.raises(CardError, match=r"'GRAIL/T-v0' is defined twice, in tasks/bad.toml$"):
        parse_card(ONE + ONE.split("\n", 1)[1], "tasks/bad.toml")


def test_duplicate_id_across_cards_names_both_files(tmp_path):
    first, second = tmp_path / "a.toml", tmp_path / "b.toml"
    first.write_text(ONE)
    second.write_text(ONE)
    with pytest.raises(CardError) as info:
        load_cards([first, second])
    assert str(first) in str(info.value) and str(second) in str(info.value)


def test_demos_names_a_dataset_beside_the_card_or_by_id(tmp_path):
    (tmp_path / "recorded").mkdir()
    for demos, expected in (("recorded", str(tmp_path / "recorded")), ("recorded/", str(tmp_path / "recorded")),
                            ("not-yet/here", str(tmp_path / "not-yet" / "here")),
                            ("my-lab/reaches-v0", "my-lab/reaches-v0"), (str(tmp_path), str(tmp_path)), ("", "")):
        (card,) = parse_card(ONE + f"demos = {demos!r}\n", "card.toml", tmp_path)
        assert card.demos == expected, demos
    (card,) = parse_card('domain = "minigrid"\n[defaults]\ndemos = "recorded"\n' + ONE.split("\n", 1)[1], "c.toml",
                         tmp_path)
    assert card.demos == str(tmp_path / "recorded")  # a default too


@pytest.fixture(scope="module")
def card_with_demos(tmp_path_factory):
    """A card file whose task takes its demonstrations from datasets exported beside it."""
    from grail_bench.task.export import export

    folder = tmp_path_factory.mktemp("cards")
    task = grail_bench.make_task("GRAIL/MiniGrid-Suboptimal-v1", turn_prob=0.5)
    export(task, [0, 1], folder / "datasets")
    card = folder / "suboptimal.toml"
    card.write_text('domain = "minigrid"\n[[task]]\nid = "GRAIL/MiniGrid-Suboptimal-v1"\nregime = "suboptimal"\n'
                    'goals = [[7, 1], [7, 7]]\nparams = { turn_prob = 0.5 }\ndemos = "datasets"\n')
    return card, task


def test_a_cards_demos_are_read_from_its_dataset(card_with_demos, monkeypatch):
    import numpy as np

    card, generated = card_with_demos
    monkeypatch.chdir(card.parent.parent)  # the card's folder, not the working directory, resolves the path
    (task,) = load_cards([card])
    assert task.demos == str(card.parent / "datasets")
    for seed in (0, 1):
        demos, expected = task.generate_demos(seed), generated.generate_demos(seed)
        assert all(np.array_equal(a.acts, b.acts) for g in task.goals for a, b in zip(demos[g], expected[g]))
    # Made through its ID, the dataset is read at once: its counts are the task's, and it must fit.
    monkeypatch.setattr(registration, "shipped_tasks", lambda: {task.id: task})
    made = registration.make_task(task.id)
    assert (made.demos, made.n_train, made.n_demos) == (task.demos, 7, 10)
    assert registration.make_task(task.id, demos="").demos == ""  # the generator instead
    with pytest.raises(grail_bench.UserError, match="its params.turn_prob = 0.5, not 0.3"):
        registration.make_task(task.id, turn_prob=0.3)
