#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! Property tests of the RTDE codec: arbitrary bytes never panic; every value of every type
//! survives a recipe's pack/unpack; decoded packages re-encode stably.

use mocomp_testkit::proptest_config;
use mocomp_ur::codec::{
    FrameDecoder, Recipe, decode_reply, decode_request, encode_reply, encode_request,
};
use mocomp_ur::types::{DataType, Value};
use proptest::prelude::*;

fn arb_value() -> impl Strategy<Value = Value> {
    let f = any::<f64>();
    prop_oneof![
        any::<bool>().prop_map(Value::Bool),
        any::<u8>().prop_map(Value::Uint8),
        any::<u32>().prop_map(Value::Uint32),
        any::<u64>().prop_map(Value::Uint64),
        any::<i32>().prop_map(Value::Int32),
        f.prop_map(Value::Double),
        prop::array::uniform3(any::<f64>()).prop_map(Value::Vector3d),
        prop::array::uniform6(any::<f64>()).prop_map(Value::Vector6d),
        prop::array::uniform6(any::<i32>()).prop_map(Value::Vector6Int32),
        prop::array::uniform6(any::<u32>()).prop_map(Value::Vector6Uint32),
    ]
}

/// Bitwise equality (NaN payloads included).
fn same(a: &Value, b: &Value) -> bool {
    let (mut x, mut y) = (Vec::new(), Vec::new());
    a.encode(&mut x);
    b.encode(&mut y);
    x == y && a.data_type() == b.data_type()
}

proptest! {
    #![proptest_config(proptest_config(2000, 0x5254_4445))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..600),
                                   step in 1usize..64) {
        let mut d = FrameDecoder::new();
        let recipe = Recipe::new(1, vec!["a".into(), "b".into()],
                                 vec![DataType::Double, DataType::Vector6Int32]);
        let mut vals = Vec::new();
        for chunk in bytes.chunks(step) {
            d.push(chunk);
            while let Ok(Some(f)) = d.next_frame() {
                for v in [1u16, 2] {
                    if let Ok(r) = decode_request(f.kind, f.payload, v) {
                        let mut b = Vec::new();
                        if encode_request(&r, v, &mut b).is_ok() {
                            let back = decode_request(b[2], &b[3..], v).unwrap();
                            let mut again = Vec::new();
                            encode_request(&back, v, &mut again).unwrap();
                            prop_assert_eq!(&again, &b);
                        }
                    }
                    if let Ok(r) = decode_reply(f.kind, f.payload, v) {
                        let mut b = Vec::new();
                        if encode_reply(&r, v, &mut b).is_ok() {
                            let back = decode_reply(b[2], &b[3..], v).unwrap();
                            let mut again = Vec::new();
                            encode_reply(&back, v, &mut again).unwrap();
                            prop_assert_eq!(&again, &b);
                        }
                    }
                }
                let _ = recipe.unpack(f.payload, &mut vals);
            }
        }
    }

    #[test]
    fn recipes_round_trip_every_type(values in prop::collection::vec(arb_value(), 1..40),
                                     version in 1u16..=2) {
        let names: Vec<String> = (0..values.len()).map(|i| format!("v{i}")).collect();
        let types: Vec<DataType> = values.iter().map(Value::data_type).collect();
        let recipe = Recipe::new(3, names, types);
        let mut b = Vec::new();
        recipe.encode_output_package(&values, version, &mut b).unwrap();
        let mut d = FrameDecoder::new();
        d.push(&b);
        let f = d.next_frame().unwrap().unwrap();
        let mocomp_ur::codec::Reply::Data { recipe_id, payload } =
            decode_reply(f.kind, f.payload, version).unwrap() else { panic!("not data") };
        prop_assert_eq!(recipe_id, (version >= 2).then_some(3));
        let mut out = Vec::new();
        recipe.unpack(payload, &mut out).unwrap();
        prop_assert_eq!(out.len(), values.len());
        for (a, b) in out.iter().zip(&values) {
            prop_assert!(same(a, b), "{:?} vs {:?}", a, b);
        }
        // One byte short is a named size error, never a panic.
        let e = recipe.unpack(&payload[..payload.len() - 1], &mut out).unwrap_err();
        prop_assert!(e.to_string().contains("recipe 3"));
    }
}
