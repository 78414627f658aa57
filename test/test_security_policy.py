"""security/policy.xml, the SROS2 access-control policy: a well-formed sros2 policy, one enclave
per node of the launch file, and each node allowed exactly the topics, services and actions it
uses (read from the running node's graph, so a publisher added to a node without the policy
fails)."""

import xml.etree.ElementTree as ET

import pytest
from conftest import REPO_ROOT
from node_helpers import launch_nodes, node_from_launch

POLICY = REPO_ROOT / "security" / "policy.xml"
ENCLAVE_ROOT = "/tactile_dock/"
OPERATOR = ENCLAVE_ROOT + "operator"  # `ros2 service call` of an operator, not a node of ours
ALLOW = "ALLOW"
# element -> (child element, attributes), as sros2's policy.xsd has them
LISTS = {
    "topics": ("topic", ("publish", "subscribe")),
    "services": ("service", ("reply", "request")),
    "actions": ("action", ("call", "execute")),
}
# What sros2's permissions template grants for an action: its topics and services.
ACTION_TOPICS = ("/_action/feedback", "/_action/status")
ACTION_SERVICES = ("/_action/send_goal", "/_action/cancel_goal", "/_action/get_result")
SIM_TIME = {"/clock"}  # subscribed only with use_sim_time: allowed, not required
# what only one enclave may publish: the forgeries that would fail an episode
SOLE_PUBLISHERS = {
    "/arm/cmd_twist": "executor",
    "/execution_report": "executor",
    "/shape_samples": "inference",
    "/contact_history": "inference",
    "/plan": "planner",
    "/episode": "planner",
    "/episode_status": "planner",
    "/terrain_prior": "perception",
}
NODES = {profile: launch_nodes(profile) for profile in ("mock", "robot")}  # profile -> name -> spec


def resolve(name: str, ns: str, node: str) -> str:
    """A policy name made absolute as sros2's permissions template does (``~`` is the node)."""
    ns = ns if ns.endswith("/") else ns + "/"
    if name.startswith("/"):
        return name
    if name.startswith("~"):
        return ns + node + name[1:]
    return ns + name


def parse_policy() -> ET.Element:
    parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
    return ET.parse(POLICY, parser).getroot()


def profiles() -> dict[str, ET.Element]:
    """Enclave path -> its one profile."""
    out = {}
    for enclave in parse_policy().find("enclaves"):
        (profile,) = enclave.find("profiles").findall("profile")
        out[enclave.get("path")] = profile
    return out


def allowed(profile: ET.Element) -> dict[str, set[str]]:
    """Permission (publish, subscribe, reply, request; call, execute: the actions) -> absolute
    names the profile allows; an action's topics and services are added as sros2 grants them
    (execute: publish and reply, call: subscribe and request)."""
    out = {kind: set() for _, kinds in LISTS.values() for kind in kinds}
    ns, node = profile.get("ns"), profile.get("node")
    for element in profile:
        for kind in LISTS.get(element.tag, ((), ()))[1]:  # comments have no permissions
            if element.get(kind) == ALLOW:
                out[kind] |= {resolve(e.text.strip(), ns, node) for e in element}
    for kind, topics, services in (
        ("execute", "publish", "reply"),
        ("call", "subscribe", "request"),
    ):
        for action in out[kind]:
            out[topics] |= {action + suffix for suffix in ACTION_TOPICS}
            out[services] |= {action + suffix for suffix in ACTION_SERVICES}
    return out


def test_the_policy_has_the_sros2_policy_structure():
    root = parse_policy()
    assert (root.tag, root.get("version")) == ("policy", "0.2.0")
    (enclaves,) = list(root)
    assert enclaves.tag == "enclaves"
    # sros2's generate_artifacts takes every child of <enclaves> for an enclave, comments too
    assert [e.tag for e in enclaves] == ["enclave"] * len(enclaves)
    for enclave in enclaves:
        assert enclave.get("path", "").startswith(ENCLAVE_ROOT)
        (profiles_element,) = list(enclave)
        assert profiles_element.tag == "profiles"
        for profile in profiles_element:
            assert profile.tag == "profile" and profile.get("ns") and profile.get("node")
            for element in profile:
                if element.tag is ET.Comment:
                    continue
                item, kinds = LISTS[element.tag]
                assert set(element.attrib) <= set(kinds), element.attrib
                assert set(element.attrib.values()) == {ALLOW}, element.attrib
                assert [e.tag for e in element] == [item] * len(element) and len(element)
                assert all(e.text and e.text.strip() == e.text for e in element)


def test_one_enclave_per_node_of_the_launch_file():
    """Every node of either profile has its enclave; the only other one is the operator's."""
    specs = {**NODES["robot"], **NODES["mock"]}
    by_path = profiles()
    assert set(by_path) == {ENCLAVE_ROOT + name for name in specs} | {OPERATOR}
    for name, spec in specs.items():
        profile = by_path[ENCLAVE_ROOT + name]
        assert profile.get("node") == spec.name
        assert profile.get("ns") == (spec.namespace or "/")


def test_each_suite_topic_has_one_publishing_enclave():
    publishers: dict[str, set[str]] = {}
    for path, profile in profiles().items():
        for topic in allowed(profile)["publish"]:
            publishers.setdefault(topic, set()).add(path.removeprefix(ENCLAVE_ROOT))
    for topic, node in SOLE_PUBLISHERS.items():
        assert publishers.get(topic) == {node}, topic
    shared = {t: p for t, p in publishers.items() if len(p) > 1}
    assert set(shared) == {"/rosout", "/parameter_events"}


def test_the_operator_may_only_call_the_dock_action_and_the_three_suite_services():
    by_path = profiles()
    operator = allowed(by_path[OPERATOR])
    assert operator["call"] == {"/dock"} and not operator["execute"]
    dock = {"/dock" + suffix for suffix in ACTION_SERVICES}
    suite = {"/start_episode", "/perception/capture", "/evaluate_hold"}
    assert operator["request"] == suite | dock
    assert operator["publish"] == {"/rosout", "/parameter_events"}
    assert operator["subscribe"] - SIM_TIME == {"/dock" + suffix for suffix in ACTION_TOPICS}
    others = [allowed(p) for k, p in by_path.items() if k != OPERATOR]
    assert operator["request"] <= set().union(*(p["reply"] for p in others))
    assert operator["call"] <= set().union(*(p["execute"] for p in others))


def names(pairs) -> set[str]:
    return {name for name, _ in pairs}


@pytest.mark.dds
@pytest.mark.parametrize(
    "profile, name",
    [pytest.param(p, n, id=f"{p}-{n}") for p, specs in NODES.items() for n in specs],
)
def test_a_node_uses_exactly_what_its_enclave_allows(profile, name, tmp_path):
    spec = NODES[profile][name]
    policy = allowed(profiles()[ENCLAVE_ROOT + name])
    with node_from_launch(spec, tmp_path) as (node, _):
        args = node.get_name(), node.get_namespace()
        published = names(node.get_publisher_names_and_types_by_node(*args))
        subscribed = names(node.get_subscriber_names_and_types_by_node(*args))
        served = names(node.get_service_names_and_types_by_node(*args))
        called = names(node.get_client_names_and_types_by_node(*args))
    assert published == policy["publish"]
    assert subscribed - SIM_TIME == policy["subscribe"] - SIM_TIME
    assert served == policy["reply"]
    assert called == policy["request"]
