-- Siemens S7-200 PPI, the master/slave protocol of the S7-200's RS-485 port, as rackd speaks
-- it (src/protocols/ppi, /work/shared/spec/ppi.md).
--
-- Frames (PROFIBUS FDL framing): SD1 `10 DA SA FC FCS 16` (the master's poll), SD2
-- `68 LE LEr 68 DA SA FC ... FCS 16`, SD3 `A2 DA SA FC data(8) FCS 16`, SD4 token
-- `DC DA SA`, and the short acknowledgement SC `E5` (or `F9`). The FCS (sum of DA..data,
-- modulo 256) is checked (s7ppi.fcs_ok). An SD2 frame's data is the S7 PDU as the S7-200
-- carries it right after FC: protocol id 32, ROSCTR, PDU reference, parameter and data
-- lengths, the error class and code (acknowledgements), then read var (04) or write var (05)
-- items (area, DB, byte.bit address, transport size, count), data items (return code,
-- transport size, length, values), PLC stop (29), PI service / RUN (28) and setup
-- communication (F0).
--
-- Serial captures name this dissector ("s7ppi") in their exported-PDU header. Over TCP (a
-- gateway) it is a Decode As choice: `-d tcp.port==2000,s7ppi`; a port preference adds one
-- port for good.

local s7ppi = Proto("s7ppi", "Siemens S7-200 PPI")

local rosctrs = { [1] = "Job", [2] = "Ack", [3] = "Ack-Data", [7] = "Userdata" }
local functions = {
    [0x04] = "Read Var", [0x05] = "Write Var", [0x28] = "PI Service (RUN)",
    [0x29] = "PLC Stop", [0xF0] = "Setup communication", [0x1A] = "Request download",
    [0x1B] = "Download block", [0x1C] = "Download ended", [0x1D] = "Start upload",
    [0x1E] = "Upload", [0x1F] = "End upload",
}
local areas = {
    [0x04] = "S", [0x05] = "SM", [0x06] = "AI", [0x07] = "AQ", [0x1E] = "C", [0x1F] = "T",
    [0x81] = "I", [0x82] = "Q", [0x83] = "M", [0x84] = "V",
}
local transport_sizes = {
    [0x01] = "BIT", [0x02] = "BYTE", [0x03] = "CHAR", [0x04] = "WORD", [0x05] = "INT",
    [0x06] = "DWORD", [0x07] = "DINT", [0x08] = "REAL", [0x1E] = "COUNTER", [0x1F] = "TIMER",
}
local data_sizes = {
    [0x00] = "NULL", [0x03] = "BIT", [0x04] = "BYTE/WORD/DWORD (length in bits)",
    [0x05] = "INTEGER (length in bits)", [0x07] = "REAL", [0x09] = "OCTET STRING",
}
-- Item return codes and error classes, as src/protocols/ppi/return_code.rs words them.
local return_codes = {
    [0x00] = "reserved", [0xFF] = "success", [0x01] = "hardware fault", [0x03] = "accessing the object not allowed",
    [0x05] = "address out of range", [0x06] = "data type not supported",
    [0x07] = "data type or size mismatch", [0x0A] = "object does not exist",
}
local error_classes = {
    [0x00] = "no error", [0x81] = "application relationship error",
    [0x82] = "object definition error", [0x83] = "no resources available",
    [0x84] = "error on service processing", [0x85] = "error on supplies (request refused)",
    [0x87] = "access error",
}
-- FDL function codes (low 4 bits of FC), requests and responses.
local request_functions = {
    [3] = "SDA low", [4] = "SDN low", [5] = "SDA high", [6] = "SDN high", [7] = "MSRD",
    [9] = "Request FDL status", [12] = "SRD low", [13] = "SRD high", [14] = "Request ident",
    [15] = "Request LSAP status",
}
local response_functions = {
    [0] = "OK", [1] = "UE (user error)", [2] = "RR (no resources)", [3] = "RS (SAP not enabled)",
    [8] = "DL (data low)", [9] = "NR (no response data)", [10] = "DH (data high)",
    [12] = "RDL (data low, not received)", [13] = "RDH (data high, not received)",
}
local starts = {
    [0x10] = "SD1 (fixed length, no data)", [0x68] = "SD2 (variable length)",
    [0xA2] = "SD3 (fixed length, 8 data bytes)", [0xDC] = "SD4 (token)",
    [0xE5] = "SC (short acknowledgement)", [0xF9] = "SC (short acknowledgement, F9)",
}

s7ppi.prefs.port = Pref.uint("TCP port", 0, "A TCP port to decode as PPI (0: none)")

local f = {
    sd = ProtoField.uint8("s7ppi.sd", "Start delimiter", base.HEX, starts),
    le = ProtoField.uint8("s7ppi.le", "Length", base.DEC),
    ler = ProtoField.uint8("s7ppi.ler", "Length repeated", base.DEC),
    da = ProtoField.uint8("s7ppi.da", "Destination address", base.DEC),
    sa = ProtoField.uint8("s7ppi.sa", "Source address", base.DEC),
    fc = ProtoField.uint8("s7ppi.fc", "Function code", base.HEX),
    fc_request = ProtoField.bool("s7ppi.fc.request", "Request", 8, nil, 0x40),
    fc_fcb = ProtoField.bool("s7ppi.fc.fcb", "Frame count bit", 8, nil, 0x20),
    fc_fcv = ProtoField.bool("s7ppi.fc.fcv", "Frame count bit valid", 8, nil, 0x10),
    fc_function = ProtoField.uint8("s7ppi.fc.function", "Function", base.DEC, nil, 0x0F),
    fcs = ProtoField.uint8("s7ppi.fcs", "Frame check sequence", base.HEX),
    fcs_computed = ProtoField.uint8("s7ppi.fcs_computed", "FCS computed", base.HEX),
    fcs_ok = ProtoField.bool("s7ppi.fcs_ok", "FCS good"),
    ed = ProtoField.uint8("s7ppi.ed", "End delimiter", base.HEX),
    ack = ProtoField.bool("s7ppi.ack", "Short acknowledgement"),
    protocol_id = ProtoField.uint8("s7ppi.protocol_id", "Protocol id", base.HEX),
    rosctr = ProtoField.uint8("s7ppi.rosctr", "ROSCTR", base.DEC, rosctrs),
    pdu_ref = ProtoField.uint16("s7ppi.pdu_ref", "PDU reference", base.DEC),
    param_length = ProtoField.uint16("s7ppi.param_length", "Parameter length", base.DEC),
    data_length = ProtoField.uint16("s7ppi.data_length", "Data length", base.DEC),
    error_class = ProtoField.uint8("s7ppi.error_class", "Error class", base.HEX, error_classes),
    error_code = ProtoField.uint8("s7ppi.error_code", "Error code", base.HEX),
    ["function"] = ProtoField.uint8("s7ppi.function", "Function", base.HEX, functions),
    item_count = ProtoField.uint8("s7ppi.item_count", "Item count", base.DEC),
    item = ProtoField.bytes("s7ppi.item", "Item"),
    transport_size = ProtoField.uint8("s7ppi.transport_size", "Transport size", base.HEX, transport_sizes),
    count = ProtoField.uint16("s7ppi.count", "Count", base.DEC),
    db = ProtoField.uint16("s7ppi.db", "DB number", base.DEC),
    area = ProtoField.uint8("s7ppi.area", "Area", base.HEX, areas),
    byte_address = ProtoField.uint32("s7ppi.byte_address", "Byte address", base.DEC),
    bit_address = ProtoField.uint8("s7ppi.bit_address", "Bit address", base.DEC),
    address = ProtoField.string("s7ppi.address", "Address"),
    return_code = ProtoField.uint8("s7ppi.return_code", "Return code", base.HEX, return_codes),
    data_size = ProtoField.uint8("s7ppi.data_transport_size", "Data transport size", base.HEX, data_sizes),
    length = ProtoField.uint16("s7ppi.length", "Length", base.DEC),
    value = ProtoField.bytes("s7ppi.value", "Values"),
    amq_calling = ProtoField.uint16("s7ppi.amq_calling", "Max AmQ calling", base.DEC),
    amq_called = ProtoField.uint16("s7ppi.amq_called", "Max AmQ called", base.DEC),
    pdu_length = ProtoField.uint16("s7ppi.pdu_length", "PDU length", base.DEC),
    block = ProtoField.string("s7ppi.block", "Program block"),
    data = ProtoField.bytes("s7ppi.data", "Data"),
}
s7ppi.fields = f

local e = {
    bad_fcs = ProtoExpert.new("s7ppi.fcs.bad", "FCS does not match", expert.group.CHECKSUM, expert.severity.ERROR),
    malformed = ProtoExpert.new("s7ppi.malformed", "Frame does not fit its length or delimiters",
        expert.group.MALFORMED, expert.severity.ERROR),
    item_error = ProtoExpert.new("s7ppi.return_code.error", "The item failed",
        expert.group.RESPONSE_CODE, expert.severity.WARN),
    refused = ProtoExpert.new("s7ppi.refused", "The PLC refused the request",
        expert.group.RESPONSE_CODE, expert.severity.WARN),
}
s7ppi.experts = { e.bad_fcs, e.malformed, e.item_error, e.refused }

local function sum(tvb, offset, len)
    local s = 0
    for i = offset, offset + len - 1 do s = (s + tvb(i, 1):uint()) % 256 end
    return s
end

-- Items of a read or write request: 12 bytes each (12 0A 10 size count(2) db(2) area addr(3)).
local function dissect_items(tvb, tree, at, stop, n)
    local names = {}
    for i = 1, n do
        if at + 12 > stop then break end
        local it = tree:add(f.item, tvb(at, 12))
        local size = tvb(at + 3, 1):uint()
        local count = tvb(at + 4, 2):uint()
        local area = tvb(at + 8, 1):uint()
        local offset = tvb(at + 9, 3):uint()
        local byte, bit = math.floor(offset / 8), offset % 8
        it:add(f.transport_size, tvb(at + 3, 1))
        it:add(f.count, tvb(at + 4, 2))
        it:add(f.db, tvb(at + 6, 2))
        it:add(f.area, tvb(at + 8, 1))
        local letter = ({ [0x01] = "", [0x02] = "B", [0x04] = "W", [0x06] = "D" })[size]
        local name
        if area == 0x1E or area == 0x1F then
            name = (areas[area]) .. offset
            it:add(f.byte_address, tvb(at + 9, 3), offset):set_text("Number: " .. offset)
        else
            it:add(f.byte_address, tvb(at + 9, 3), byte)
            it:add(f.bit_address, tvb(at + 9, 3), bit)
            name = (areas[area] or string.format("area %02X", area))
            if size == 0x01 then
                name = name .. byte .. "." .. bit
            else
                name = name .. (letter or "") .. byte
            end
        end
        if count > 1 then name = name .. " x" .. count end
        it:add(f.address, tvb(at + 8, 4), name):set_generated()
        it:set_text("Item " .. i .. ": " .. name)
        names[i] = name
        at = at + 12
    end
    return names, at
end

-- Data items: return code, transport size, length (bits for sizes 3, 4, 5), values.
local function dissect_data(tvb, tree, at, stop, n, names)
    local shown = {}
    for i = 1, n do
        if at + 1 > stop then break end
        local rc = tvb(at, 1):uint()
        local di = tree:add(f.data, tvb(at, math.min(4, stop - at)))
        di:set_text("Data item " .. i .. (names and names[i] and (": " .. names[i]) or ""))
        local rc_item = di:add(f.return_code, tvb(at, 1))
        if rc ~= 0xFF and rc ~= 0x00 then rc_item:add_proto_expert_info(e.item_error) end
        shown[#shown + 1] = return_codes[rc] or string.format("return code %02X", rc)
        if at + 4 > stop then break end
        local size = tvb(at + 1, 1):uint()
        local len = tvb(at + 2, 2):uint()
        di:add(f.data_size, tvb(at + 1, 1))
        di:add(f.length, tvb(at + 2, 2))
        local bytes = (size == 3 or size == 4 or size == 5) and math.ceil(len / 8) or len
        bytes = math.min(bytes, stop - at - 4)
        if bytes > 0 then
            di:add(f.value, tvb(at + 4, bytes))
            di:set_len(4 + bytes)
        end
        at = at + 4 + bytes
        if bytes % 2 == 1 and i < n then at = at + 1 end -- a fill byte between items
    end
    return shown
end

-- The S7 PDU; returns an Info text.
local function dissect_pdu(tvb, tree, at, stop)
    if stop - at < 10 or tvb(at, 1):uint() ~= 0x32 then
        if stop > at then tree:add(f.data, tvb(at, stop - at)) end
        return ""
    end
    local pdu = tree:add(f.data, tvb(at, stop - at))
    pdu:set_text("S7 PDU")
    pdu:add(f.protocol_id, tvb(at, 1))
    local rosctr = tvb(at + 1, 1):uint()
    pdu:add(f.rosctr, tvb(at + 1, 1))
    pdu:add(f.pdu_ref, tvb(at + 4, 2))
    pdu:add(f.param_length, tvb(at + 6, 2))
    pdu:add(f.data_length, tvb(at + 8, 2))
    local plen, dlen = tvb(at + 6, 2):uint(), tvb(at + 8, 2):uint()
    local p = at + 10
    local info = rosctrs[rosctr] or ("ROSCTR " .. rosctr)
    if rosctr == 2 or rosctr == 3 then
        if stop - p < 2 then return info end
        local class, code = tvb(p, 1):uint(), tvb(p + 1, 1):uint()
        pdu:add(f.error_class, tvb(p, 1))
        pdu:add(f.error_code, tvb(p + 1, 1))
        p = p + 2
        if class ~= 0 or code ~= 0 then
            pdu:add_proto_expert_info(e.refused)
            return string.format("%s refused: class %02X code %02X (%s)", info, class, code,
                error_classes[class] or "unknown error class")
        end
    end
    if plen == 0 or p + plen > stop then return info end
    local fn = tvb(p, 1):uint()
    pdu:add(f["function"], tvb(p, 1))
    info = info .. " " .. (functions[fn] or string.format("function %02X", fn))
    local dstart = p + plen
    local dstop = math.min(dstart + dlen, stop)
    if (fn == 0x04 or fn == 0x05) and plen >= 2 then
        local n = tvb(p + 1, 1):uint()
        pdu:add(f.item_count, tvb(p + 1, 1))
        if rosctr == 1 then
            local names = dissect_items(tvb, pdu, p + 2, dstart, n)
            info = info .. " " .. table.concat(names, ", ")
            if fn == 0x05 then dissect_data(tvb, pdu, dstart, dstop, n, names) end
        else
            local shown = dissect_data(tvb, pdu, dstart, dstop, n, nil)
            info = info .. ": " .. table.concat(shown, ", ")
        end
    elseif fn == 0xF0 and plen >= 8 then
        pdu:add(f.amq_calling, tvb(p + 2, 2))
        pdu:add(f.amq_called, tvb(p + 4, 2))
        pdu:add(f.pdu_length, tvb(p + 6, 2))
    elseif (fn == 0x28 or fn == 0x29) and rosctr == 1 and plen >= 2 then
        local name_len = tvb(p + plen - 1, 1):uint()
        if name_len > 0 and name_len < plen then
            pdu:add(f.block, tvb(p + plen - name_len, name_len))
        end
    end
    return info
end

local function add_fc(tree, tvb, at)
    local fc = tvb(at, 1):uint()
    local item = tree:add(f.fc, tvb(at, 1))
    item:add(f.fc_request, tvb(at, 1))
    local request = fc >= 0x40 and fc % 0x80 >= 0x40
    if request then
        item:add(f.fc_fcb, tvb(at, 1))
        item:add(f.fc_fcv, tvb(at, 1))
    end
    item:add(f.fc_function, tvb(at, 1))
    local names = request and request_functions or response_functions
    item:append_text(" (" .. (request and "request, " or "response, ") .. (names[fc % 16] or "reserved") .. ")")
    return fc
end

-- Length of the frame at offset, or nil when the bytes do not start one.
local function frame_length(tvb, offset)
    local left = tvb:len() - offset
    local sd = tvb(offset, 1):uint()
    if sd == 0xE5 or sd == 0xF9 then return 1 end
    if sd == 0x10 then return 6 end
    if sd == 0xA2 then return 14 end
    if sd == 0xDC then return 3 end
    if sd == 0x68 then
        if left < 2 then return nil end
        return tvb(offset + 1, 1):uint() + 6
    end
    return nil
end

local function check_fcs(tree, tvb, body, len, fcs_at)
    local computed = sum(tvb, body, len)
    local item = tree:add(f.fcs, tvb(fcs_at, 1))
    item:add(f.fcs_computed, tvb(fcs_at, 1), computed):set_generated()
    local ok = computed == tvb(fcs_at, 1):uint()
    item:add(f.fcs_ok, tvb(fcs_at, 1), ok):set_generated()
    if not ok then item:add_proto_expert_info(e.bad_fcs) end
    return ok
end

-- One frame of `len` bytes at offset; returns an Info text and the addresses.
local function dissect_frame(tvb, tree, offset, len)
    local sd = tvb(offset, 1):uint()
    tree:add(f.sd, tvb(offset, 1))
    if sd == 0xE5 or sd == 0xF9 then
        tree:add(f.ack, tvb(offset, 1), true):set_generated()
        return "SC acknowledgement"
    end
    if sd == 0xDC then
        tree:add(f.da, tvb(offset + 1, 1))
        tree:add(f.sa, tvb(offset + 2, 1))
        return "Token", tvb(offset + 1, 1):uint(), tvb(offset + 2, 1):uint()
    end
    local body, body_len
    if sd == 0x68 then
        tree:add(f.le, tvb(offset + 1, 1))
        tree:add(f.ler, tvb(offset + 2, 1))
        if tvb(offset + 1, 1):uint() ~= tvb(offset + 2, 1):uint() or tvb(offset + 3, 1):uint() ~= 0x68
            or tvb(offset + 1, 1):uint() < 3 then
            tree:add_proto_expert_info(e.malformed)
            return "SD2 with a bad header"
        end
        body, body_len = offset + 4, len - 6
    else
        body, body_len = offset + 1, len - 3
    end
    local da, sa = tvb(body, 1):uint(), tvb(body + 1, 1):uint()
    tree:add(f.da, tvb(body, 1))
    tree:add(f.sa, tvb(body + 1, 1))
    local fc = add_fc(tree, tvb, body + 2)
    local info
    if sd == 0x10 then
        info = string.format("SD1 FC %02X%s", fc, fc % 16 == 12 and fc >= 0x40 and " (poll)" or "")
    elseif sd == 0xA2 then
        tree:add(f.data, tvb(body + 3, 8))
        info = string.format("SD3 FC %02X", fc)
    else
        info = string.format("SD2 FC %02X ", fc) .. dissect_pdu(tvb, tree, body + 3, body + body_len)
    end
    local ok = check_fcs(tree, tvb, body, body_len, body + body_len)
    local ed_item = tree:add(f.ed, tvb(offset + len - 1, 1))
    if tvb(offset + len - 1, 1):uint() ~= 0x16 then ed_item:add_proto_expert_info(e.malformed) end
    if not ok then info = info .. " [FCS error]" end
    return info, da, sa
end

function s7ppi.dissector(tvb, pinfo, root)
    pinfo.cols.protocol = "PPI"
    pinfo.cols.info:clear()
    local offset = 0
    local tcp = pinfo.port_type == 2
    while offset < tvb:len() do
        local len = frame_length(tvb, offset)
        if not len then
            if tcp and tvb:len() - offset < 2 then
                pinfo.desegment_offset = offset
                pinfo.desegment_len = DESEGMENT_ONE_MORE_SEGMENT
                return tvb:len()
            end
            local tree = root:add(s7ppi, tvb(offset))
            tree:add(f.data, tvb(offset))
            tree:add_proto_expert_info(e.malformed)
            return tvb:len()
        end
        if tvb:len() - offset < len then
            if tcp then
                pinfo.desegment_offset = offset
                pinfo.desegment_len = len - (tvb:len() - offset)
                return tvb:len()
            end
            local tree = root:add(s7ppi, tvb(offset))
            tree:add(f.sd, tvb(offset, 1))
            tree:add_proto_expert_info(e.malformed)
            return tvb:len()
        end
        local tree = root:add(s7ppi, tvb(offset, len))
        local info, da, sa = dissect_frame(tvb, tree, offset, len)
        pinfo.cols.info:append(info .. "  ")
        if not tcp and da then
            pinfo.cols.src = "PPI " .. sa
            pinfo.cols.dst = "PPI " .. da
        end
        offset = offset + len
    end
    return offset
end

local registered_port = 0
function s7ppi.prefs_changed()
    local tcp = DissectorTable.get("tcp.port")
    if registered_port ~= 0 then tcp:remove(registered_port, s7ppi) end
    registered_port = s7ppi.prefs.port
    if registered_port ~= 0 then tcp:add(registered_port, s7ppi) end
end

DissectorTable.get("tcp.port"):add_for_decode_as(s7ppi)
