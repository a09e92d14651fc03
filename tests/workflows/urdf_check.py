"""What ROS's URDF parsers ask of a URDF document, checked with Python's own XML parser."""

from __future__ import annotations

import xml.etree.ElementTree as ET


def loadable_urdf(text: str) -> tuple[str, str, dict[str, ET.Element]]:
    """What ROS's URDF parsers need (urdfdom's check_urdf, urdf_parser_py): well-formed XML, one <robot
    name=...>, links declared once, every joint fixed between declared links, one root link, no link with
    two parents. Returns the robot's name, the root link and the joints by child link."""
    robot = ET.fromstring(text.encode())
    assert robot.tag == "robot" and robot.get("name")
    links = [link.get("name") for link in robot.findall("link")]
    assert all(links) and len(set(links)) == len(links)
    joints = {}
    for joint in robot.findall("joint"):
        parent, child = joint.find("parent"), joint.find("child")
        assert joint.get("name") and joint.get("type") == "fixed" and parent is not None and child is not None
        assert parent.get("link") in links and child.get("link") in links and child.get("link") not in joints
        joints[child.get("link")] = joint
    roots = [name for name in links if name not in joints]
    assert len(roots) == 1 and len({j.get("name") for j in joints.values()}) == len(joints)
    return robot.get("name"), roots[0], joints
