"""The counterfactual search's answer read as a ranking of the scene's concepts."""

from policy import failing_test_task
from search import SearchConfig, SearchResult, counterfactual_search
from search.ranking import concept_ranking
from sim.core.visible import visible_concepts


def test_the_best_edit_comes_first_and_every_visible_concept_is_ranked(nav, nav_policy):
    for shift in ("object_ti", "distractor_ti"):
        task, _ = failing_test_task(nav, nav_policy, shift, 0)
        result = counterfactual_search(
            nav, nav_policy, task.scene, nav.demonstrate(task), config=SearchConfig()
        )
        ranking = concept_ranking(nav.space, task.scene, result)
        visible = sorted(uc.name for uc in visible_concepts(nav.space, task.scene))
        assert sorted(ranking) == visible
        best = {nav.space.user_concept(c.slot, c.concept).name for c in result.best.edit.changes}
        assert set(ranking[: len(best)]) == best
        assert ranking[0] == nav.space.user_concept(*task.cause).name  # the planted cause


def test_no_candidates_leave_the_space_order(nav):
    scene = nav.test_task("distractor_ti", 0).scene
    ranking = concept_ranking(nav.space, scene, SearchResult((), (), None, 2))
    assert ranking == tuple(uc.name for uc in visible_concepts(nav.space, scene))
