//! A J1939 NAME in a configuration file (the controller's config, the simulator's machine file):
//! its fields by name, every one required, each checked against its width in `excavator.dbc`'s
//! `AddressClaimed` message.
//!
//! ```toml
//! [j1939.name]
//! identity_number = 1          # 21 bits: the unit's serial number
//! manufacturer_code = 0        # 11 bits
//! ecu_instance = 0             # 3 bits
//! function_instance = 0        # 5 bits
//! function = 130               # 8 bits
//! vehicle_system = 0           # 7 bits
//! vehicle_system_instance = 0  # 4 bits
//! industry_group = 3           # 3 bits: construction
//! arbitrary_address_capable = false  # the project's addresses are fixed
//! ```
//!
//! The fields, their keys and their widths are [`crate::address_claim::NAME_FIELDS`], the one list;
//! a [`NameConfig`] is [`crate::address_claim::NameFields`] (serde with `gateway_core`'s `std`
//! feature) and [`NameConfig::name`] the checked NAME. A test holds the example above to that list.

pub use crate::address_claim::{
    NameFieldError as NameConfigError, NameFields as NameConfig, NameRule,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::address_claim::{CONTROLLER_NAME, GATEWAY_NAME, NAME_FIELDS, Name};

    /// The example of the module docs names every field of [`NAME_FIELDS`] in order, each with its
    /// width: the docs cannot drift from the DBC.
    #[test]
    fn the_documented_example_matches_the_field_list() {
        let source = include_str!("name_config.rs");
        let example: Vec<&str> = source
            .lines()
            .take_while(|l| l.starts_with("//!"))
            .skip_while(|l| !l.contains("[j1939.name]"))
            .skip(1)
            .take_while(|l| !l.contains("```"))
            .collect();
        assert_eq!(example.len(), NAME_FIELDS.len(), "{example:?}");
        for (line, field) in example.iter().zip(NAME_FIELDS) {
            let line = line.trim_start_matches("//!").trim();
            assert!(line.starts_with(&format!("{} = ", field.key)), "{line}");
            if field.key != "arbitrary_address_capable" {
                assert!(
                    line.contains(&format!("# {} bits", field.signal.len)),
                    "{line}: {} bits",
                    field.signal.len
                );
            }
        }
    }

    #[test]
    fn the_default_names_round_trip() {
        for name in [CONTROLLER_NAME, GATEWAY_NAME] {
            assert_eq!(NameConfig::from(name).name(), Ok(name));
        }
    }

    #[test]
    fn every_field_is_checked_against_its_width() {
        let ok = NameConfig::from(CONTROLLER_NAME);
        let cases: [(&str, NameConfig, u64, u32); 8] = [
            (
                "identity_number",
                NameConfig {
                    identity_number: 1 << 21,
                    ..ok
                },
                1 << 21,
                21,
            ),
            (
                "manufacturer_code",
                NameConfig {
                    manufacturer_code: 2048,
                    ..ok
                },
                2048,
                11,
            ),
            (
                "ecu_instance",
                NameConfig {
                    ecu_instance: 8,
                    ..ok
                },
                8,
                3,
            ),
            (
                "function_instance",
                NameConfig {
                    function_instance: 32,
                    ..ok
                },
                32,
                5,
            ),
            (
                "vehicle_system",
                NameConfig {
                    vehicle_system: 128,
                    ..ok
                },
                128,
                7,
            ),
            (
                "vehicle_system_instance",
                NameConfig {
                    vehicle_system_instance: 16,
                    ..ok
                },
                16,
                4,
            ),
            (
                "industry_group",
                NameConfig {
                    industry_group: 8,
                    ..ok
                },
                8,
                3,
            ),
            (
                "arbitrary_address_capable",
                NameConfig {
                    arbitrary_address_capable: true,
                    ..ok
                },
                1,
                1,
            ),
        ];
        for (field, config, value, bits) in cases {
            let err = config.name().expect_err(field);
            assert_eq!((err.field, err.value), (field, value), "{err}");
            if field != "arbitrary_address_capable" {
                assert!(err.to_string().contains(&format!("{bits} bits")), "{err}");
            }
        }
        // The widest values fit.
        let widest = NameConfig {
            identity_number: (1 << 21) - 1,
            manufacturer_code: 2047,
            ecu_instance: 7,
            function_instance: 31,
            function: 255,
            vehicle_system: 127,
            vehicle_system_instance: 15,
            industry_group: 7,
            arbitrary_address_capable: false,
        };
        assert_eq!(
            widest.name().map(Name::raw),
            Ok(0x7FFF_FFFF_FFFF_FFFF - (1 << 48))
        );
    }

    #[test]
    fn a_table_with_a_missing_or_unknown_field_is_refused() {
        let full = toml::to_string(&NameConfig::from(GATEWAY_NAME)).expect("serialises");
        assert_eq!(
            toml::from_str::<NameConfig>(&full).ok().map(|c| c.name()),
            Some(Ok(GATEWAY_NAME))
        );
        let missing = full.replace("function = 129\n", "");
        assert!(toml::from_str::<NameConfig>(&missing).is_err());
        let unknown = format!("{full}serial = 3\n");
        assert!(toml::from_str::<NameConfig>(&unknown).is_err());
    }
}
