"""Hypothesis strategies for constraint trees and RTC profiles."""

from __future__ import annotations

import string
from datetime import UTC, datetime, timedelta, timezone, tzinfo
from typing import Any, TypeVar

from hypothesis import settings
from hypothesis import strategies as st

from openel_async.rtc import constraints as c
from openel_async.rtc.profile import (
    ActionDoc,
    Actions,
    ActionStatus,
    ActivityType,
    BasicDoc,
    BasicInfo,
    BasicInfoExt,
    ComponentType,
    ConfigurationDoc,
    ConfigurationExt,
    ConfigurationProfile,
    ConfigurationSetProfile,
    DataPortDoc,
    DataPortExt,
    DataPortProfile,
    ExtraValue,
    InterfaceDirection,
    Language,
    LanguageExt,
    Library,
    Parameter,
    PortType,
    Position,
    Property,
    RtcProfile,
    ServiceInterfaceDoc,
    ServiceInterfaceExt,
    ServiceInterfaceProfile,
    ServicePortDoc,
    ServicePortExt,
    ServicePortProfile,
    TargetEnvironment,
    TransMethod,
)

_T = TypeVar("_T")

# Deterministic: a fixed seed per test and no example database on disk.
SETTINGS = settings(derandomize=True, database=None, deadline=None, max_examples=60)

# Text both formats can carry: no surrogates and no C0 controls except \t \n \r.
TEXT = st.text(
    st.characters(exclude_categories=("Cs", "Cc", "Cn"), include_characters="\t\n\r"),
    max_size=12,
)
NAME = st.text(string.ascii_letters + string.digits + "_", min_size=1, max_size=8)
OPT_TEXT = st.none() | TEXT

# --- constraint trees with an exact text form --------------------------------------

NUMBER = st.one_of(
    st.integers(-(10**6), 10**6).map(str),
    st.decimals(-(10**4), 10**4, places=3, allow_nan=False, allow_infinity=False).map(str),
)
# Characters of literals, enumeration items and hash keys in the text form.
WORD = st.text(
    st.characters(whitelist_categories=("L", "N"), whitelist_characters="_-.+*/#@!?%&$~"),
    min_size=1,
    max_size=6,
).filter(lambda s: s != "x")


@st.composite
def ranges(draw: st.DrawFn) -> c.Constraint:
    low, high = sorted([draw(st.integers(-1000, 1000)), draw(st.integers(-1000, 1000))])
    low_incl, high_incl = draw(st.booleans()), draw(st.booleans())
    if low_incl and high_incl:
        return c.Between(str(low), str(high))
    lower = c.GreaterThanOrEqualTo(str(low)) if low_incl else c.GreaterThan(str(low))
    upper = c.LessThanOrEqualTo(str(high)) if high_incl else c.LessThan(str(high))
    return c.And((lower, upper))


TEXT_UNIT = st.one_of(
    st.builds(c.EqualTo, WORD),
    st.builds(c.LessThan, NUMBER),
    st.builds(c.LessThanOrEqualTo, NUMBER),
    st.builds(c.GreaterThan, NUMBER),
    st.builds(c.GreaterThanOrEqualTo, NUMBER),
    ranges(),
    st.lists(WORD, min_size=1, max_size=4).map(lambda v: c.Enumeration(tuple(v))),
)
TEXT_CONSTRAINT = st.one_of(
    TEXT_UNIT,
    st.lists(TEXT_UNIT, min_size=2, max_size=4).map(lambda u: c.ListConstraint(tuple(u))),
    st.dictionaries(WORD, TEXT_UNIT, min_size=1, max_size=4).map(
        lambda d: c.HashConstraint(tuple(d.items()))
    ),
)

# --- arbitrary trees (for the YAML/XML forms) --------------------------------------

LIKE = st.builds(
    c.Like,
    st.text(string.ascii_letters + "*?", max_size=8),
    st.just("*"),
    st.just("?"),
    st.just("\\"),
)
LEAF = st.one_of(
    *[st.builds(cls, TEXT, st.booleans()) for cls in c.COMPARISONS],
    st.builds(c.Between, TEXT, TEXT),
    LIKE,
    st.just(c.IsNull()),
    st.builds(c.Enumeration, st.lists(TEXT, min_size=1, max_size=3).map(tuple), st.booleans()),
)


def _as_unit(tree: c.Constraint) -> c.Constraint:
    """Hash entries must be units; wrapping in Not keeps the tree general."""
    return tree if c.is_unit(tree) else c.Not(tree)


def _branches(inner: st.SearchStrategy[c.Constraint]) -> st.SearchStrategy[c.Constraint]:
    children = st.lists(inner, min_size=1, max_size=2)
    return st.one_of(
        st.builds(c.Not, inner),
        st.builds(lambda first, rest: c.And((first, *rest)), inner, children),
        # A first child that is not an equality: an ``or`` of equalities alone reads
        # back as an Enumeration by design (tested separately).
        st.builds(lambda first, rest: c.Or((first, *rest)), LIKE, children),
        children.map(lambda ch: c.ListConstraint(tuple(ch))),
        st.dictionaries(TEXT.filter(bool), inner.map(_as_unit), min_size=1, max_size=3).map(
            lambda d: c.HashConstraint(tuple(d.items()))
        ),
    )


ANY_CONSTRAINT = st.recursive(LEAF, _branches, max_leaves=8)

# --- profiles ----------------------------------------------------------------------

ZONES: st.SearchStrategy[tzinfo | None] = st.sampled_from([None, UTC, timezone(timedelta(hours=9))])
# hypothesis' stub types ``timezones`` narrower than the API accepts.
DATES = st.datetimes(datetime(1000, 1, 1), datetime(9999, 1, 1), timezones=ZONES)  # type: ignore[arg-type]
PROPERTIES = st.lists(st.builds(Property, name=NAME, value=OPT_TEXT), max_size=2).map(tuple)


def extras(*, nested: bool) -> st.SearchStrategy[dict[str, ExtraValue]]:
    """Unknown keys; YAML keeps nested lists/maps, XML is tested with attributes."""
    keys = st.from_regex(r"rtcExt::custom[A-Z][a-z]{0,4}", fullmatch=True)
    if not nested:
        return st.dictionaries(keys, TEXT, max_size=2)
    leaf: st.SearchStrategy[ExtraValue] = st.none() | TEXT
    value: st.SearchStrategy[ExtraValue] = st.recursive(
        leaf,
        lambda inner: st.lists(inner, max_size=2) | st.dictionaries(NAME, inner, max_size=2),
        max_leaves=4,
    )
    return st.dictionaries(keys, value, max_size=2)


@st.composite
def profiles(draw: st.DrawFn, *, nested_extras: bool) -> RtcProfile:
    def doc(cls: type[_T], fields: list[str]) -> _T:
        return draw(st.builds(cls, **{f: OPT_TEXT for f in fields}))

    basic = BasicInfo(
        name=draw(NAME),
        component_type=draw(st.sampled_from(ComponentType)),
        activity_type=draw(st.sampled_from(ActivityType)),
        component_kind=draw(NAME),
        category=draw(NAME),
        execution_type=draw(NAME),
        vendor=draw(NAME),
        version=draw(NAME),
        creation_date=draw(DATES),
        update_date=draw(DATES),
        rtc_type=draw(OPT_TEXT),
        description=draw(OPT_TEXT),
        execution_rate=draw(st.none() | st.floats(allow_nan=False, allow_infinity=False)),
        max_instances=draw(st.none() | st.integers()),
        abstract=draw(OPT_TEXT),
        hardware_profile=draw(OPT_TEXT),
        doc=doc(BasicDoc, ["algorithm", "description", "inout", "creator", "license"]),
        ext=BasicInfoExt(
            comment=draw(OPT_TEXT),
            save_project=draw(OPT_TEXT),
            version_up_logs=tuple(draw(st.lists(TEXT, max_size=2))),
            properties=draw(PROPERTIES),
        ),
        extra=draw(extras(nested=nested_extras)),
    )
    action_names = draw(
        st.sets(st.sampled_from(["on_initialize", "on_execute", "on_mode_changed"]))
    )
    statuses: dict[str, Any] = {
        n: ActionStatus(
            implemented=draw(st.booleans()),
            doc=doc(ActionDoc, ["description", "pre_condition", "post_condition"]),
        )
        for n in action_names
    }
    actions = Actions(**statuses)
    config_names = draw(st.lists(NAME, unique=True, max_size=3))
    config_set = draw(
        st.none()
        | st.just(
            ConfigurationSetProfile(
                configurations=tuple(
                    ConfigurationProfile(
                        name=n,
                        type=draw(st.sampled_from(["double", "int", "string", "vector<long>"])),
                        default_value=draw(TEXT),
                        unit=draw(OPT_TEXT),
                        constraint=draw(st.none() | ANY_CONSTRAINT),
                        doc=doc(ConfigurationDoc, ["description", "range", "constraint"]),
                        ext=ConfigurationExt(
                            comment=draw(OPT_TEXT),
                            variable_name=draw(OPT_TEXT),
                            properties=draw(PROPERTIES),
                        ),
                    )
                    for n in config_names
                )
            )
        )
    )
    port_names = draw(st.lists(NAME, unique=True, max_size=4))
    split = draw(st.integers(0, len(port_names)))
    data_ports = tuple(
        DataPortProfile(
            port_type=draw(st.sampled_from(PortType)),
            name=n,
            type=draw(NAME),
            idl_file=draw(OPT_TEXT),
            dataflow_type=draw(OPT_TEXT),
            constraint=draw(st.none() | ANY_CONSTRAINT),
            doc=doc(DataPortDoc, ["description", "type", "semantics"]),
            ext=draw(
                st.none()
                | st.builds(
                    DataPortExt,
                    position=st.sampled_from(Position),
                    comment=OPT_TEXT,
                    variable_name=OPT_TEXT,
                    properties=PROPERTIES,
                )
            ),
            extra=draw(extras(nested=nested_extras)),
        )
        for n in port_names[:split]
    )
    service_ports = tuple(
        ServicePortProfile(
            name=n,
            interfaces=tuple(
                ServiceInterfaceProfile(
                    name=i,
                    type=draw(NAME),
                    direction=draw(st.sampled_from(InterfaceDirection)),
                    instance_name=draw(OPT_TEXT),
                    path=draw(OPT_TEXT),
                    doc=doc(ServiceInterfaceDoc, ["description", "doc_return"]),
                    ext=ServiceInterfaceExt(variable_name=draw(OPT_TEXT)),
                )
                for i in draw(st.lists(NAME, unique=True, max_size=2))
            ),
            trans_methods=tuple(TransMethod(kind=k) for k in draw(st.lists(NAME, max_size=2))),
            doc=doc(ServicePortDoc, ["description", "ifdescription"]),
            ext=draw(st.none() | st.builds(ServicePortExt, position=st.sampled_from(Position))),
        )
        for n in port_names[split:]
    )
    targets = st.builds(
        TargetEnvironment,
        lang_version=OPT_TEXT,
        os=OPT_TEXT,
        os_versions=st.lists(TEXT, max_size=2).map(tuple),
        cpus=st.lists(TEXT, max_size=2).map(tuple),
        libraries=st.lists(
            st.builds(Library, name=NAME, version=OPT_TEXT, other=OPT_TEXT), max_size=2
        ).map(tuple),
    )
    language = draw(
        st.none()
        | st.builds(
            Language,
            kind=NAME,
            ext=st.none()
            | st.builds(
                LanguageExt,
                targets=st.lists(targets, min_size=1, max_size=2).map(tuple),
                properties=PROPERTIES,
            ),
        )
    )
    return RtcProfile(
        id=draw(NAME),
        version=draw(NAME),
        basic_info=basic,
        actions=actions,
        configuration_set=config_set,
        data_ports=data_ports,
        service_ports=service_ports,
        parameters=tuple(
            Parameter(name=n, default_value=draw(OPT_TEXT))
            for n in draw(st.lists(NAME, max_size=2))
        ),
        language=language,
        extra=draw(extras(nested=nested_extras)),
    )
